#include "tessera/pipeline/flow_graph.h"

#include <chrono>
#include <thread>

#include <oneapi/tbb/flow_graph.h>
#include <oneapi/tbb/task_arena.h>

namespace tessera::pipeline {

namespace flow = oneapi::tbb::flow;

namespace {

// A message with its frame's place in the stream.
template <class T>
struct Numbered {
  std::uint64_t number = 0;
  T item;
};

}  // namespace

int defaultThreadCount() {
  const unsigned hardware = std::thread::hardware_concurrency();
  return hardware == 0 ? 1 : static_cast<int>(hardware);
}

void runGraph(SourceStage& source, TrackingStage& tracking, IntegrationStage& integration,
              PlaneStage& planes, TextureStage& textures, const DescribeStage& describer,
              CommitStage& committer, StatsSink& sink, const GraphOptions& options) {
  const int threads = options.threads > 0 ? options.threads : defaultThreadCount();
  oneapi::tbb::task_arena arena(threads);
  arena.execute([&] {
    flow::graph graph;

    // Each frame gets a number at the source, and a sequencer in front of each serial stage
    // hands it the frames in that order: a serial function_node alone does not keep the order
    // its messages came in, and a plane stage that saw two frames swapped found other patches.
    std::uint64_t next_frame = 0;
    flow::input_node<Numbered<core::Frame>> source_node(
        graph, [&](oneapi::tbb::flow_control& control) {
          std::optional<core::Frame> frame = source.next();
          if (!frame) {
            control.stop();
            return Numbered<core::Frame>{};
          }
          return Numbered<core::Frame>{next_frame++, std::move(*frame)};
        });
    // Replay: never drop a frame; hold the source back instead.
    flow::limiter_node<Numbered<core::Frame>> limiter(
        graph, static_cast<std::size_t>(options.max_frames_in_flight));
    // Serial stages in a row: while frame N is integrated, frame N+1 is tracked and frame N-1
    // goes through plane detection.
    auto numbered = [](const auto& message) { return message.number; };
    flow::sequencer_node<Numbered<core::Frame>> to_tracking(graph, numbered);
    flow::function_node<Numbered<core::Frame>, Numbered<TrackedFrame>> tracking_node(
        graph, flow::serial, [&](Numbered<core::Frame> frame) {
          return Numbered<TrackedFrame>{frame.number, tracking.process(std::move(frame.item))};
        });
    flow::sequencer_node<Numbered<TrackedFrame>> to_integration(graph, numbered);
    flow::function_node<Numbered<TrackedFrame>, Numbered<FusedFrame>> integration_node(
        graph, flow::serial, [&](Numbered<TrackedFrame> tracked) {
          return Numbered<FusedFrame>{tracked.number, integration.process(std::move(tracked.item))};
        });
    flow::sequencer_node<Numbered<FusedFrame>> to_planes(graph, numbered);
    // The plane stage sends the frame on to the sink and each patch it finalized to texturing,
    // numbered in finalization order.
    std::size_t next_sequence = 0, next_batch = 0;
    auto jobsOf = [&](std::vector<planes::PatchSnapshot>& patches, std::uint64_t frame_index) {
      std::vector<PatchJob> jobs;
      const auto now = std::chrono::steady_clock::now();
      for (planes::PatchSnapshot& patch : patches) {
        jobs.push_back(
            {next_sequence++, next_batch, patches.size(), frame_index, std::move(patch), now, {}});
      }
      if (!jobs.empty()) ++next_batch;
      patches.clear();
      return jobs;
    };
    // Patches merged into others leave the database in the same order.
    auto retirementsOf = [&](const std::vector<planes::PatchEvent>& events) {
      std::vector<PatchJob> jobs;
      for (const planes::PatchEvent& event : events) {
        if (event.kind != planes::PatchEvent::Kind::kRetired) continue;
        PatchJob job;
        job.sequence = next_sequence++;
        job.retired = event.id;
        jobs.push_back(std::move(job));
      }
      return jobs;
    };
    using PlanesNode =
        flow::multifunction_node<Numbered<FusedFrame>, std::tuple<Numbered<FusedFrame>, PatchJob>>;
    PlanesNode planes_node(
        graph, flow::serial, [&](Numbered<FusedFrame> fused, PlanesNode::output_ports_type& out) {
          fused.item = planes.process(std::move(fused.item));
          for (PatchJob& job : retirementsOf(fused.item.patch_events)) {
            std::get<1>(out).try_put(std::move(job));
          }
          for (PatchJob& job : jobsOf(fused.item.finalized_patches, fused.item.frame.index)) {
            std::get<1>(out).try_put(std::move(job));
          }
          std::get<0>(out).try_put(std::move(fused));
        });
    // Bitmaps are built and described independently: as many at once as there are free
    // threads, off the frame path. They are matched and committed one at a time, in
    // finalization order.
    flow::function_node<PatchJob, DescribedPatch> describe_node(
        graph, flow::unlimited, [&](const PatchJob& job) { return describer.process(job); });
    flow::sequencer_node<DescribedPatch> in_order(
        graph, [](const DescribedPatch& described) { return described.sequence; });
    flow::function_node<DescribedPatch, flow::continue_msg> commit_node(
        graph, flow::serial, [&](DescribedPatch described) {
          if (described.retired) {
            committer.retire(*described.retired);
            return flow::continue_msg{};
          }
          const DescribedPatch::Batch batch = described.batchInfo();
          std::optional<texture::PatchBitmap> bitmap = described.bitmap;
          const CommitRecord record = committer.process(std::move(described));
          textures.keep(std::move(bitmap));
          const CommitStage::Economy economy = committer.economy();
          MonitorCommit totals;
          totals.textures_stored = committer.texturesStored();
          totals.patterns_stored = committer.patternsStored();
          totals.textured_patches = economy.textured_patches;
          totals.reuses = economy.reuses;
          totals.bytes_before = economy.bytes_before;
          totals.bytes_after = economy.bytes_after;
          sink.writeCommit(record, batch.index, batch.size, batch.frame_index, totals);
          return flow::continue_msg{};
        });
    flow::sequencer_node<Numbered<FusedFrame>> to_sink(graph, numbered);
    flow::function_node<Numbered<FusedFrame>, flow::continue_msg> sink_node(
        graph, flow::serial, [&](const Numbered<FusedFrame>& fused) {
          sink.process(fused.item);
          return flow::continue_msg{};
        });

    flow::make_edge(source_node, limiter);
    flow::make_edge(limiter, to_tracking);
    flow::make_edge(to_tracking, tracking_node);
    flow::make_edge(tracking_node, to_integration);
    flow::make_edge(to_integration, integration_node);
    flow::make_edge(integration_node, to_planes);
    flow::make_edge(to_planes, planes_node);
    flow::make_edge(flow::output_port<0>(planes_node), to_sink);
    flow::make_edge(to_sink, sink_node);
    flow::make_edge(flow::output_port<1>(planes_node), describe_node);
    flow::make_edge(describe_node, in_order);
    flow::make_edge(in_order, commit_node);
    flow::make_edge(sink_node, limiter.decrementer());

    source_node.activate();
    graph.wait_for_all();

    // End of stream: the patches still live are finalized and textured like the others.
    std::vector<planes::PatchSnapshot> finalized;
    const std::vector<planes::PatchEvent> events = planes.finishStream(finalized);
    sink.writePatchEvents(events);
    const std::uint64_t end_index = sink.framesDone();
    for (PatchJob& job : retirementsOf(events)) describe_node.try_put(std::move(job));
    for (PatchJob& job : jobsOf(finalized, end_index)) describe_node.try_put(std::move(job));
    graph.wait_for_all();
  });
  sink.flush();
}

}  // namespace tessera::pipeline
