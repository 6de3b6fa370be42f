#include "internal/sqlite_texture_rows.h"

#include <string>

#include "internal/texture_codec.h"
#include "tessera/core/error.h"

namespace tessera::db::internal {

const char* const kInsertTexture =
    "INSERT INTO textures (kind, width, height, texel_m, png, ccv, feature_kind, keypoints, "
    "descriptors, lattice_v1x, lattice_v1y, lattice_v2x, lattice_v2y, content_key, run_id, "
    "source_patch, name) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)";

const char* const kSelectTexture =
    "SELECT kind, width, height, texel_m, png, ccv, feature_kind, keypoints, descriptors, "
    "lattice_v1x, lattice_v1y, lattice_v2x, lattice_v2y, content_key, run_id, source_patch, "
    "name FROM textures WHERE id = ?";

TextureRecord recordOf(const Statement& row, std::int64_t id) {
  TextureRecord r;
  r.id = id;
  r.kind = parseKind(row.text(0));
  r.texel_m = row.real(3);
  decodePng(row.blobData(4), row.blobSize(4), r.rgb, r.mask);
  if (r.rgb.cols != row.int64(1) || r.rgb.rows != row.int64(2)) {
    throw core::Error("PNG size differs from the stored width and height");
  }
  r.ccv = decodeFloats(row.blobData(5), row.blobSize(5));
  r.feature_kind = row.text(6);
  r.keypoints = decodeKeypoints(row.blobData(7), row.blobSize(7));
  r.descriptors = decodeDescriptors(row.blobData(8), row.blobSize(8));
  if (!row.isNull(9)) {
    r.lattice = Lattice{{row.real(9), row.real(10)}, {row.real(11), row.real(12)}};
  }
  r.content_key = row.text(13);
  r.run_id = row.int64(14);  // NULL (imported) reads as 0
  r.source_patch = static_cast<int>(row.int64(15));
  r.name = row.text(16);
  return r;
}

std::int64_t insertTexture(Statement& insert, Connection& db, const EncodedTexture& encoded) {
  const TextureRecord& r = *encoded.record;
  insert.reset();
  insert.bind(1, std::string(kindName(r.kind)))
      .bind(2, std::int64_t{r.rgb.cols})
      .bind(3, std::int64_t{r.rgb.rows})
      .bind(4, r.texel_m)
      .bindBlob(5, encoded.png.data(), encoded.png.size())
      .bindBlob(6, encoded.ccv.data(), encoded.ccv.size())
      .bind(7, r.feature_kind)
      .bindBlob(8, encoded.keypoints.data(), encoded.keypoints.size())
      .bindBlob(9, encoded.descriptors.data(), encoded.descriptors.size());
  if (r.lattice) {
    insert.bind(10, r.lattice->v1.x()).bind(11, r.lattice->v1.y());
    insert.bind(12, r.lattice->v2.x()).bind(13, r.lattice->v2.y());
  }  // else the lattice columns stay NULL (reset() clears bindings)
  insert.bind(14, encoded.content_key);
  if (r.run_id != 0) insert.bind(15, r.run_id);
  insert.bind(16, std::int64_t{r.source_patch}).bind(17, r.name).run();
  return db.lastInsertId();
}

}  // namespace tessera::db::internal
