#pragma once
// The TSDF surface of a map continued over several sessions (`tessera run --continue`): each
// session fuses its own TSDF, and the map's surface is the newest session's, with the earlier
// surface kept where the newest session did not see.
#include "tessera/fusion/tsdf_map.h"

namespace tessera::fusion {

// `later` whole, and the triangles of `earlier` none of whose vertices lies within overlap_m
// of a vertex of `later` (where both saw a place, the later view of it stands).
SurfaceMesh mergeSurfaces(const SurfaceMesh& earlier, const SurfaceMesh& later, double overlap_m);

}  // namespace tessera::fusion
