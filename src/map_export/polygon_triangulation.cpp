// A patch outline (outer boundary and holes) as triangles: a constrained Delaunay triangulation
// (CGAL) of all the boundary edges, keeping the faces an odd number of boundaries deep.
#include <deque>
#include <map>

#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_face_base_with_info_2.h>

#include "tessera/map_export/map_model.h"

namespace tessera::map_export {

namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
// Per face: how many boundaries separate it from the outside (-1: not reached yet).
using FaceBase =
    CGAL::Triangulation_face_base_with_info_2<int, Kernel,
                                              CGAL::Constrained_triangulation_face_base_2<Kernel>>;
using Tds =
    CGAL::Triangulation_data_structure_2<CGAL::Triangulation_vertex_base_2<Kernel>, FaceBase>;
// Exact_predicates_tag: boundaries that cross (a simplified outline may) are split where they
// do, at an approximate point.
using Cdt = CGAL::Constrained_Delaunay_triangulation_2<Kernel, Tds, CGAL::Exact_predicates_tag>;

void insertRing(Cdt& cdt, const planes::Polygon2& ring) {
  if (ring.size() < 3) return;
  for (std::size_t i = 0; i < ring.size(); ++i) {
    const Eigen::Vector2d& a = ring[i];
    const Eigen::Vector2d& b = ring[(i + 1) % ring.size()];
    if (a == b) continue;
    cdt.insert_constraint(Kernel::Point_2(a.x(), a.y()), Kernel::Point_2(b.x(), b.y()));
  }
}

// Breadth-first from the infinite face: crossing a constrained edge adds one to the depth.
void markDepths(Cdt& cdt) {
  for (auto f = cdt.all_faces_begin(); f != cdt.all_faces_end(); ++f) f->info() = -1;
  std::deque<std::pair<Cdt::Face_handle, int>> queue{{cdt.infinite_face(), 0}};
  // Faces across a boundary wait in `next` until their whole depth level is done.
  while (!queue.empty()) {
    std::deque<std::pair<Cdt::Face_handle, int>> next;
    while (!queue.empty()) {
      auto [face, depth] = queue.front();
      queue.pop_front();
      if (face->info() != -1) continue;
      face->info() = depth;
      for (int i = 0; i < 3; ++i) {
        const Cdt::Face_handle neighbour = face->neighbor(i);
        if (neighbour->info() != -1) continue;
        if (cdt.is_constrained(Cdt::Edge(face, i))) {
          next.push_back({neighbour, depth + 1});
        } else {
          queue.push_back({neighbour, depth});
        }
      }
    }
    queue = std::move(next);
  }
}

}  // namespace

PlanarTriangles triangulatePolygon(const planes::OutlinePart& part) {
  Cdt cdt;
  insertRing(cdt, part.outer);
  for (const planes::Polygon2& hole : part.holes) insertRing(cdt, hole);
  PlanarTriangles out;
  if (cdt.dimension() < 2) return out;
  markDepths(cdt);
  std::map<Cdt::Vertex_handle, std::uint32_t> index;
  const auto indexOf = [&](Cdt::Vertex_handle v) {
    const auto [it, added] = index.try_emplace(v, static_cast<std::uint32_t>(out.vertices.size()));
    if (added) out.vertices.emplace_back(v->point().x(), v->point().y());
    return it->second;
  };
  for (auto f = cdt.finite_faces_begin(); f != cdt.finite_faces_end(); ++f) {
    if (f->info() % 2 != 1) continue;  // outside, or inside a hole
    out.triangles.push_back({indexOf(f->vertex(0)), indexOf(f->vertex(1)), indexOf(f->vertex(2))});
  }
  return out;
}

}  // namespace tessera::map_export
