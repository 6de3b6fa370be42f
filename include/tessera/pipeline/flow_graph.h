#pragma once
// The one place that knows the topology: source -> limiter -> tracking -> integration ->
// planes -> stats sink, with the patches the plane stage finalizes going on to texturing and
// description (many patches at once) -> a sequencer (finalization order) -> the serial match
// and commit to the texture database, as a tbb::flow::graph inside a task_arena of the requested
// concurrency.
#include "tessera/pipeline/stages.h"
#include "tessera/pipeline/texture_db_stages.h"

namespace tessera::pipeline {

struct GraphOptions {
  int threads = 0;               // 0: hardware threads
  int max_frames_in_flight = 4;  // replay back-pressure (limiter_node)
};

// Runs the stages over the whole stream, then flushes them in order (end of stream).
// Blocks until done.
void runGraph(SourceStage& source, TrackingStage& tracking, IntegrationStage& integration,
              PlaneStage& planes, TextureStage& textures, const DescribeStage& describer,
              CommitStage& committer, StatsSink& sink, const GraphOptions& options);

// Hardware threads, at least 1.
int defaultThreadCount();

}  // namespace tessera::pipeline
