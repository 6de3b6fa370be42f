#include "tessera/pipeline/flow_graph.h"

#include <thread>

#include <oneapi/tbb/flow_graph.h>
#include <oneapi/tbb/task_arena.h>

namespace tessera::pipeline {

namespace flow = oneapi::tbb::flow;

int defaultThreadCount() {
  const unsigned hardware = std::thread::hardware_concurrency();
  return hardware == 0 ? 1 : static_cast<int>(hardware);
}

void runGraph(SourceStage& source, TrackingStage& tracking, IntegrationStage& integration,
              PlaneStage& planes, TextureStage& textures, StatsSink& sink,
              const GraphOptions& options) {
  const int threads = options.threads > 0 ? options.threads : defaultThreadCount();
  oneapi::tbb::task_arena arena(threads);
  arena.execute([&] {
    flow::graph graph;

    flow::input_node<core::Frame> source_node(graph, [&](oneapi::tbb::flow_control& control) {
      std::optional<core::Frame> frame = source.next();
      if (!frame) {
        control.stop();
        return core::Frame{};
      }
      return std::move(*frame);
    });
    // Replay: never drop a frame; hold the source back instead.
    flow::limiter_node<core::Frame> limiter(graph,
                                            static_cast<std::size_t>(options.max_frames_in_flight));
    // Serial stages in a row: while frame N is integrated, frame N+1 is tracked and frame N-1
    // goes through plane detection.
    flow::function_node<core::Frame, TrackedFrame> tracking_node(
        graph, flow::serial, [&](core::Frame frame) { return tracking.process(std::move(frame)); });
    flow::function_node<TrackedFrame, FusedFrame> integration_node(
        graph, flow::serial,
        [&](TrackedFrame tracked) { return integration.process(std::move(tracked)); });
    // The plane stage sends the frame on to the sink and each patch it finalized to texturing.
    using PlanesNode =
        flow::multifunction_node<FusedFrame, std::tuple<FusedFrame, planes::PatchSnapshot>>;
    PlanesNode planes_node(graph, flow::serial,
                           [&](FusedFrame fused, PlanesNode::output_ports_type& out) {
                             fused = planes.process(std::move(fused));
                             for (planes::PatchSnapshot& patch : fused.finalized_patches) {
                               std::get<1>(out).try_put(std::move(patch));
                             }
                             fused.finalized_patches.clear();
                             std::get<0>(out).try_put(std::move(fused));
                           });
    // Bitmaps are independent: as many are built at once as there are free threads.
    using MaybeBitmap = std::optional<texture::PatchBitmap>;
    flow::function_node<planes::PatchSnapshot, MaybeBitmap> texture_node(
        graph, flow::unlimited,
        [&](const planes::PatchSnapshot& patch) { return textures.build(patch); });
    flow::function_node<MaybeBitmap, flow::continue_msg> bitmap_store_node(
        graph, flow::serial, [&](MaybeBitmap bitmap) {
          textures.keep(std::move(bitmap));
          return flow::continue_msg{};
        });
    flow::function_node<FusedFrame, flow::continue_msg> sink_node(graph, flow::serial,
                                                                  [&](const FusedFrame& fused) {
                                                                    sink.process(fused);
                                                                    return flow::continue_msg{};
                                                                  });

    flow::make_edge(source_node, limiter);
    flow::make_edge(limiter, tracking_node);
    flow::make_edge(tracking_node, integration_node);
    flow::make_edge(integration_node, planes_node);
    flow::make_edge(flow::output_port<0>(planes_node), sink_node);
    flow::make_edge(flow::output_port<1>(planes_node), texture_node);
    flow::make_edge(texture_node, bitmap_store_node);
    flow::make_edge(sink_node, limiter.decrementer());

    source_node.activate();
    graph.wait_for_all();

    // End of stream: the patches still live are finalized and textured like the others.
    std::vector<planes::PatchSnapshot> finalized;
    sink.writePatchEvents(planes.finish(finalized));
    for (planes::PatchSnapshot& patch : finalized) texture_node.try_put(std::move(patch));
    graph.wait_for_all();
  });
  sink.flush();
}

}  // namespace tessera::pipeline
