#include "services/floorplan/rooms/delaunay_mesh.h"

#include <CGAL/Delaunay_triangulation_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Hilbert_policy_tags.h>
#include <CGAL/Hilbert_sort_2.h>
#include <CGAL/Spatial_sort_traits_adapter_2.h>
#include <CGAL/Triangulation_face_base_with_info_2.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>
#include <CGAL/property_map.h>

#include <cstdint>
#include <exception>
#include <numeric>
#include <utility>

#include "absl/strings/str_cat.h"

namespace carvemap::floorplan_internal {
namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Vb = CGAL::Triangulation_vertex_base_with_info_2<uint32_t, K>;
using Fb = CGAL::Triangulation_face_base_with_info_2<int, K>;
using Tds = CGAL::Triangulation_data_structure_2<Vb, Fb>;
using Delaunay = CGAL::Delaunay_triangulation_2<K, Tds>;
using CPoint = K::Point_2;

}  // namespace

struct DelaunayMesh::Impl {
  Delaunay dt;
  std::vector<Delaunay::Face_handle> faces;  // by face id, for Locate's hints
};

DelaunayMesh::DelaunayMesh() : impl_(std::make_unique<Impl>()) {}
DelaunayMesh::DelaunayMesh(DelaunayMesh&&) noexcept = default;
DelaunayMesh& DelaunayMesh::operator=(DelaunayMesh&&) noexcept = default;
DelaunayMesh::~DelaunayMesh() = default;

absl::StatusOr<DelaunayMesh> DelaunayMesh::Build(const std::vector<Eigen::Vector2d>& points,
                                                 const char* who) {
  DelaunayMesh out;
  Delaunay& dt = out.impl_->dt;
  try {
    std::vector<uint32_t> ins(points.size());
    std::iota(ins.begin(), ins.end(), 0u);
    std::vector<CPoint> cpts;
    cpts.reserve(points.size());
    for (const Eigen::Vector2d& p : points) cpts.emplace_back(p.x(), p.y());
    auto pmap = CGAL::make_property_map(cpts);
    using SortTraits = CGAL::Spatial_sort_traits_adapter_2<K, decltype(pmap)>;
    CGAL::Hilbert_sort_2<SortTraits, CGAL::Hilbert_sort_median_policy> sort(SortTraits{pmap});
    sort(ins.begin(), ins.end());
    Delaunay::Face_handle hint;
    for (uint32_t i : ins) {
      const Delaunay::Vertex_handle vh = dt.insert(cpts[i], hint);
      vh->info() = i;
      hint = vh->face();
    }
  } catch (const std::exception& e) {
    return absl::InternalError(absl::StrCat(who, ": CGAL triangulation failed: ", e.what()));
  }
  int nf = 0;
  for (auto f = dt.finite_faces_begin(); f != dt.finite_faces_end(); ++f) f->info() = nf++;
  for (auto f = dt.all_faces_begin(); f != dt.all_faces_end(); ++f) {
    if (dt.is_infinite(f)) f->info() = -1;
  }
  out.triangles_.resize(nf);
  out.neighbours_.resize(nf);
  out.impl_->faces.resize(nf);
  for (auto f = dt.finite_faces_begin(); f != dt.finite_faces_end(); ++f) {
    out.impl_->faces[f->info()] = f;
    for (int i = 0; i < 3; ++i) {
      out.triangles_[f->info()][i] = static_cast<int>(f->vertex(i)->info());
      out.neighbours_[f->info()][i] = f->neighbor(i)->info();
    }
  }
  return out;
}

int DelaunayMesh::dimension() const { return impl_->dt.dimension(); }

PointLocation DelaunayMesh::Locate(const Eigen::Vector2d& q, int* hint) const {
  const Delaunay& dt = impl_->dt;
  const Delaunay::Face_handle start = *hint >= 0 ? impl_->faces[*hint] : Delaunay::Face_handle();
  Delaunay::Locate_type lt;
  int li = -1;
  const Delaunay::Face_handle fh = dt.locate(CPoint(q.x(), q.y()), lt, li, start);
  PointLocation s;
  switch (lt) {
    case Delaunay::VERTEX:
      s.kind = PointLocation::kVertex;
      s.id = static_cast<int>(fh->vertex(li)->info());
      break;
    case Delaunay::EDGE:
      s.kind = PointLocation::kEdge;
      if (dt.is_infinite(fh)) {
        const Delaunay::Face_handle other = fh->neighbor(li);
        s.id = other->info();
        s.edge = other->index(fh);
      } else {
        s.id = fh->info();
        s.edge = li;
      }
      break;
    case Delaunay::FACE:
      s.kind = PointLocation::kFace;
      s.id = fh->info();
      break;
    default:
      break;  // outside the convex hull
  }
  if (!dt.is_infinite(fh)) *hint = fh->info();
  return s;
}

std::vector<Eigen::Vector2d> Circumcentres(const std::vector<Eigen::Vector2d>& points,
                                           const std::vector<std::array<int, 3>>& triangles) {
  std::vector<Eigen::Vector2d> out(triangles.size());
  for (size_t f = 0; f < triangles.size(); ++f) {
    const Eigen::Vector2d &a = points[triangles[f][0]], &b = points[triangles[f][1]],
                          &c = points[triangles[f][2]];
    const CPoint cc =
        CGAL::circumcenter(CPoint(a.x(), a.y()), CPoint(b.x(), b.y()), CPoint(c.x(), c.y()));
    out[f] = Eigen::Vector2d(cc.x(), cc.y());
  }
  return out;
}

}  // namespace carvemap::floorplan_internal
