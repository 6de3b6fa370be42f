#pragma once
// The monitor's page (src/monitor/page/index.html), embedded at build time.
namespace tessera::monitor {
extern const char* const kPage;
}
