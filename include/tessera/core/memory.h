#pragma once
// The process's memory as a long run watches it (docs/METRICS.md, "Memory"): what the kernel
// holds for it, and how much of that the program actually uses.

namespace tessera::core {

// Resident memory now (/proc/self/statm), MB; 0 where it cannot be read.
double residentMb();
// Bytes the program has allocated and not freed (glibc's mallinfo2: in use in every arena,
// plus blocks mapped on their own), MB. Resident memory above it is freed memory glibc
// keeps, or the code and libraries.
double heapInUseMb();
// Returns the free pages glibc holds in every arena to the kernel (malloc_trim). Frees made
// on many threads leave such pages in many arenas, where the kernel cannot take them back.
void returnFreedMemory();

}  // namespace tessera::core
