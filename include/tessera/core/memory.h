#pragma once
// The process's memory as a long run watches it (`rss_mb` and `heap_mb` in stats.jsonl,
// docs/METRICS.md): what the kernel holds for it, and how much of that the program uses.

namespace tessera::core {

// Resident memory now (/proc/self/statm), MB; 0 where it cannot be read.
double residentMb();
// Bytes the program has allocated and not freed (glibc's mallinfo2: in use in every arena,
// plus blocks mapped on their own), MB. Resident memory above it is freed memory glibc
// keeps, or the code and libraries. Walks every arena's free lists: about 1 ms on a heap of
// 1 GB, so sample it sparingly.
double heapInUseMb();
// Returns the free pages glibc holds in every arena to the kernel (malloc_trim). Frees made
// on many threads leave such pages in many arenas, where the kernel cannot take them back.
void returnFreedMemory();
// Lets glibc keep freed memory for reuse instead of handing it back to the kernel at every
// free: blocks up to 32 MB come from the heap (not mapped on their own), and free space at a
// heap's top is kept up to 128 MB. A frame's images, point clouds and pyramids are then
// allocated again in pages already resident, instead of being faulted in afresh each frame
// (8 % of the CPU of a replay); returnFreedMemory(), called every few seconds, bounds what
// is kept. Threads share at most `arenas` arenas (at least 2): each arena's free top is kept,
// and with glibc's default (8 per core) a dozen threads' arenas held 300 to 500 MB freed
// between them on the loop ring. runPipeline calls it as a run starts, with its thread count
// (mallopt is safe with other threads running; threads that already have an arena keep it).
// Skipped when GLIBC_TUNABLES sets malloc tunables: the user's choice stands.
void keepFreedMemoryForReuse(int arenas);
// Whether GLIBC_TUNABLES sets any glibc.malloc tunable (then the functions here leave glibc's
// settings as the user made them).
bool userSetMallocTunables();
// Once the frames are over: free space at a heap's top above 16 MB is handed back at the next
// large free, and what every arena holds now is returned. The threads' own arenas (64 MB each)
// never trim their tops under keepFreedMemoryForReuse's 128 MB, and malloc_trim leaves those
// tops alone; the end of a run (the last patches, the TSDF rebuilt, the mesh extracted) then
// peaks on top of them. On the frame path the lower threshold would fault a frame's buffers in
// afresh (15 % more CPU a frame on the loop ring); after it, no such churn is left. Skipped like
// keepFreedMemoryForReuse.
void returnFreedMemorySooner();

}  // namespace tessera::core
