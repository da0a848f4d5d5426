// The orientation predicate the floor plans' triangulation walks share (room_labeling.cc,
// eigencrust.cc). Includes CGAL's kernel: include it from .cc files only.
#pragma once

#include <cmath>

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <Eigen/Core>

namespace carvemap::floorplan_internal {

// Sign of the turn a→b→c: +1 left, −1 right, 0 collinear. A Shewchuk-style static filter on
// doubles (ccwerrboundA) decides almost every case, CGAL's exact Epick predicate the rest: the
// walks rely on consistent signs (a vertex exactly on a segment must be seen as such).
inline int Orient(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c) {
  using K = CGAL::Exact_predicates_inexact_constructions_kernel;
  const double detl = (b.x() - a.x()) * (c.y() - a.y());
  const double detr = (b.y() - a.y()) * (c.x() - a.x());
  const double det = detl - detr;
  const double bound = 3.3306690738754716e-16 * (std::abs(detl) + std::abs(detr));
  if (det > bound) return 1;
  if (-det > bound) return -1;
  return static_cast<int>(CGAL::orientation(K::Point_2(a.x(), a.y()), K::Point_2(b.x(), b.y()),
                                            K::Point_2(c.x(), c.y())));
}

}  // namespace carvemap::floorplan_internal
