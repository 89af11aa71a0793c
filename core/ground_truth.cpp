#include "core/ground_truth.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <limits>
#include <mutex>
#include <tuple>

namespace rcb {
namespace {

double magnitude_of(const Vec3d& a, const Vec3d& b) {
    return std::max({std::abs(a.x), std::abs(a.y), std::abs(a.z), std::abs(b.x), std::abs(b.y), std::abs(b.z)});
}

/// Box shrunk by eps per side; an axis thinner than 2·eps collapses to its mid-plane.
Aabbd shrunk(const Aabbd& b, double eps) {
    Aabbd s;
    for (int a = 0; a < 3; ++a) {
        s.min[a] = b.min[a] + eps;
        s.max[a] = b.max[a] - eps;
        if (s.min[a] > s.max[a]) s.min[a] = s.max[a] = 0.5 * (b.min[a] + b.max[a]);
    }
    return s;
}

Aabbd grown(const Aabbd& b, double eps) { return {b.min - Vec3d{eps, eps, eps}, b.max + Vec3d{eps, eps, eps}}; }

/// ε in segment parameter units: moving an end point by ε (L∞) changes t by ε / max|d_a|.
double t_tolerance(const SegmentSlabsd& slabs, double eps) {
    const double longest = 1.0 / std::min({std::abs(slabs.inv.x), std::abs(slabs.inv.y), std::abs(slabs.inv.z)});
    if (eps == 0) return 0;
    return longest > 0 ? eps / longest : std::numeric_limits<double>::infinity();
}

Contact classify_prepared(const SegmentSlabsd& slabs, const Aabbd& box, double eps) {
    const double dt = t_tolerance(slabs, eps);
    double tn, tf;
    if (!slabs.clip(grown(box, eps), tn, tf, -dt, 1 + dt)) return Contact::miss;
    // Shortened by dt at both ends; a segment shorter than 2ε shrinks to its midpoint.
    const double t0 = std::min(dt, 0.5), t1 = std::max(1 - dt, 0.5);
    return slabs.clip(shrunk(box, eps), tn, tf, t0, t1) ? Contact::hit : Contact::touch;
}

}  // namespace

Contact classify_contact(const Segmentd& s, const Aabbd& box) {
    double eps = kRelativeTolerance * std::max(magnitude_of(s.p0, s.p1), magnitude_of(box.min, box.max));
    return classify_prepared(SegmentSlabsd(s), box, eps);
}

GroundTruth::GroundTruth(const std::vector<Object>& objects) {
    const std::size_t n = objects.size();
    for (int a = 0; a < 3; ++a) {
        min_[a].resize(n);
        max_[a].resize(n);
    }
    magnitude_.resize(n);
    uids_.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
        const Aabbd b = objects[i].box.as<double>();
        for (int a = 0; a < 3; ++a) {
            min_[a][i] = b.min[a];
            max_[a][i] = b.max[a];
        }
        magnitude_[i] = magnitude_of(b.min, b.max);
        uids_[i] = objects[i].uid;
    }
}

void GroundTruth::classify(const Segment& segment, std::vector<Uid>& must, std::vector<Uid>& touch) const {
    must.clear();
    touch.clear();
    const Segmentd s{segment.p0.as<double>(), segment.p1.as<double>()};
    const SegmentSlabsd slabs(s);
    const double seg_mag = magnitude_of(s.p0, s.p1);
    const double longest = 1.0 / std::min({std::abs(slabs.inv.x), std::abs(slabs.inv.y), std::abs(slabs.inv.z)});
    const double t_per_eps = longest > 0 ? 1.0 / longest : std::numeric_limits<double>::infinity();
    const std::size_t n = uids_.size();
    // Cheap filter first, vectorisable: the segment against every box grown by its ε.
    constexpr std::size_t kBlock = 1024;
    std::uint8_t candidate[kBlock];
    for (std::size_t begin = 0; begin < n; begin += kBlock) {
        const std::size_t end = std::min(n, begin + kBlock);
        for (std::size_t i = begin; i < end; ++i) {
            const double eps = kRelativeTolerance * std::max(seg_mag, magnitude_[i]);
            // The segment lengthened by ε at both ends (see classify_prepared).
            const double dt = eps > 0 ? eps * t_per_eps : 0.0;
            double tn = -dt, tf = 1.0 + dt;
            for (int a = 0; a < 3; ++a) {
                const double near = slabs.near_is_max[a] ? max_[a][i] + eps : min_[a][i] - eps;
                const double far = slabs.near_is_max[a] ? min_[a][i] - eps : max_[a][i] + eps;
                const double lo = (near - slabs.origin[a]) * slabs.inv[a];
                const double hi = (far - slabs.origin[a]) * slabs.inv[a];
                tn = max_ignoring_nan(lo, tn);
                tf = min_ignoring_nan(hi, tf);
            }
            candidate[i - begin] = tn <= tf;
        }
        for (std::size_t i = begin; i < end; ++i) {
            if (!candidate[i - begin]) continue;
            const double eps = kRelativeTolerance * std::max(seg_mag, magnitude_[i]);
            const Aabbd box{{min_[0][i], min_[1][i], min_[2][i]}, {max_[0][i], max_[1][i], max_[2][i]}};
            const Contact c = classify_prepared(slabs, box, eps);
            if (c == Contact::hit)
                must.push_back(uids_[i]);
            else if (c == Contact::touch)
                touch.push_back(uids_[i]);
        }
    }
    std::sort(must.begin(), must.end());
    std::sort(touch.begin(), touch.end());
}

Verification GroundTruth::verify(std::span<const Segment> rays, const HitLists& hits, std::size_t max_examples) const {
    Verification total;
    std::mutex merge;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, rays.size(), 8),
                      [&](const tbb::blocked_range<std::size_t>& range) {
                          Verification local;
                          std::vector<Uid> must, touch, reported;
                          auto note = [&](std::size_t ray, Uid uid, Discrepancy::Kind kind) {
                              if (local.examples.size() < max_examples)
                                  local.examples.push_back({static_cast<std::uint32_t>(ray), uid, kind});
                          };
                          for (std::size_t r = range.begin(); r != range.end(); ++r) {
                              classify(rays[r], must, touch);
                              auto got = hits.of(r);
                              reported.assign(got.begin(), got.end());
                              std::sort(reported.begin(), reported.end());
                              // Duplicates first (adjacent after sorting), then a merge walk over the sorted sets.
                              for (std::size_t i = 1; i < reported.size(); ++i)
                                  if (reported[i] == reported[i - 1]) {
                                      ++local.duplicate;
                                      note(r, reported[i], Discrepancy::duplicate);
                                  }
                              auto last = std::unique(reported.begin(), reported.end());
                              reported.erase(last, reported.end());
                              std::size_t m = 0;
                              for (Uid uid : reported) {
                                  while (m < must.size() && must[m] < uid) {
                                      ++local.missed;
                                      note(r, must[m], Discrepancy::missed);
                                      ++m;
                                  }
                                  if (m < must.size() && must[m] == uid) {
                                      ++m;
                                      continue;
                                  }
                                  if (!std::binary_search(touch.begin(), touch.end(), uid)) {
                                      ++local.extra;
                                      note(r, uid, Discrepancy::extra);
                                  }
                              }
                              for (; m < must.size(); ++m) {
                                  ++local.missed;
                                  note(r, must[m], Discrepancy::missed);
                              }
                          }
                          std::lock_guard<std::mutex> lock(merge);
                          total.missed += local.missed;
                          total.extra += local.extra;
                          total.duplicate += local.duplicate;
                          total.examples.insert(total.examples.end(), local.examples.begin(), local.examples.end());
                      });
    // Every chunk kept its first examples; keep the first of all, so the examples do not depend
    // on how the rays were split among threads.
    std::sort(total.examples.begin(), total.examples.end(), [](const Discrepancy& a, const Discrepancy& b) {
        return std::tie(a.ray, a.uid) < std::tie(b.ray, b.uid);
    });
    if (total.examples.size() > max_examples) total.examples.resize(max_examples);
    return total;
}

}  // namespace rcb
