#pragma once
// CPU time, the figure a robot budgets (docs/METRICS.md, "CPU"): user plus system seconds.

namespace tessera::core {

// Of the whole process, every thread together, since it started.
double processCpuSeconds();
// Of the calling thread since it started.
double threadCpuSeconds();

}  // namespace tessera::core
