#include "tessera/pipeline/flow_graph.h"

#include <chrono>
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
              PlaneStage& planes, TextureStage& textures, const MatchStage& matcher,
              CommitStage& committer, StatsSink& sink, const GraphOptions& options) {
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
    // The plane stage sends the frame on to the sink and each patch it finalized to texturing,
    // numbered in finalization order.
    std::size_t next_sequence = 0, next_batch = 0;
    auto jobsOf = [&](std::vector<planes::PatchSnapshot>& patches, std::uint64_t frame_index) {
      std::vector<PatchJob> jobs;
      const auto now = std::chrono::steady_clock::now();
      for (planes::PatchSnapshot& patch : patches) {
        jobs.push_back(
            {next_sequence++, next_batch, patches.size(), frame_index, std::move(patch), now});
      }
      if (!jobs.empty()) ++next_batch;
      patches.clear();
      return jobs;
    };
    using PlanesNode = flow::multifunction_node<FusedFrame, std::tuple<FusedFrame, PatchJob>>;
    PlanesNode planes_node(
        graph, flow::serial, [&](FusedFrame fused, PlanesNode::output_ports_type& out) {
          fused = planes.process(std::move(fused));
          for (PatchJob& job : jobsOf(fused.finalized_patches, fused.frame.index)) {
            std::get<1>(out).try_put(std::move(job));
          }
          std::get<0>(out).try_put(std::move(fused));
        });
    // Bitmaps are built and matched independently: as many at once as there are free threads,
    // off the frame path. They are committed one at a time, in finalization order.
    flow::function_node<PatchJob, MatchedPatch> match_node(
        graph, flow::unlimited, [&](const PatchJob& job) { return matcher.process(job); });
    flow::sequencer_node<MatchedPatch> in_order(
        graph, [](const MatchedPatch& matched) { return matched.sequence; });
    flow::function_node<MatchedPatch, flow::continue_msg> commit_node(
        graph, flow::serial, [&](MatchedPatch matched) {
          const MatchedPatch::Batch batch = matched.batchInfo();
          std::optional<texture::PatchBitmap> bitmap = matched.bitmap;
          const CommitRecord record = committer.process(std::move(matched));
          textures.keep(std::move(bitmap));
          sink.writeCommit(record, batch.index, batch.size, batch.frame_index,
                           committer.texturesStored());
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
    flow::make_edge(flow::output_port<1>(planes_node), match_node);
    flow::make_edge(match_node, in_order);
    flow::make_edge(in_order, commit_node);
    flow::make_edge(sink_node, limiter.decrementer());

    source_node.activate();
    graph.wait_for_all();

    // End of stream: the patches still live are finalized and textured like the others.
    std::vector<planes::PatchSnapshot> finalized;
    sink.writePatchEvents(planes.finish(finalized));
    const std::uint64_t end_index = sink.framesDone();
    for (PatchJob& job : jobsOf(finalized, end_index)) match_node.try_put(std::move(job));
    graph.wait_for_all();
  });
  sink.flush();
}

}  // namespace tessera::pipeline
