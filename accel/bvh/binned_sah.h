#pragma once
/// The binned SAH split that the dynamic BVH's rebuild (dynamic_bvh.cpp, one binary node at a time)
/// and the wide BVH's builder (wide_bvh_build.cpp, resumable, several splits per wide node) share.
/// Wald 2007, "On fast construction of SAH-based bounding volume hierarchies", section 3: the
/// centroids' bounds are cut into `bins` equal intervals per axis, every object goes to the bin of
/// its centroid, and one sweep per axis over the bins' unions and counts prices each border at
/// area(left) · n_left + area(right) · n_right (the SAH of the thesis' §3.5.4, eq. 3.2, with the
/// parent's area and the traversal cost left out, as they are the same for every border); the
/// cheapest border splits, the first axis and the lowest border on ties. The thesis' §6.4.2
/// (Table 6.4) replaces the DBVH's incremental builder by such a full SAH build.
///
/// What the two builders do differently stays theirs, as parameters:
/// - `Real`, the type of the bin index arithmetic, the areas and the costs: float for the dynamic
///   BVH, double for the wide BVH (areas of boxes near the coordinate limit overflow float);
/// - the partition: the dynamic BVH's std::partition of the whole range (sah_partition), the wide
///   BVH's two cursors that stop and resume within a budget (SahPartition);
/// - the fallback when no border leaves objects on both sides although the centroids spread:
///   the dynamic BVH splits by size (split_by_size), the wide BVH at the median of the widest
///   centroid axis (split_at_median); both split by size when every centroid coincides;
/// - the centroid (each caller fills SahItem::centroid) and when to stop (one object per leaf, or
///   `leaf_size`): the callers'.

#include <algorithm>
#include <array>
#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

#include "core/base/geometry.h"

namespace rcb {

/// An object during a build: its box, its centroid, and an id (a leaf node, or a uid) that breaks
/// ties of the fallbacks.
struct SahItem {
    Aabb box;
    Vec3 centroid;
    std::uint32_t id;
};

/// Half the surface area of `b` in `Real`, 0 for the empty box.
template <class Real>
Real sah_area(const Aabb& b) {
    if (b.is_empty()) return Real(0);
    const Real x = Real(b.max.x) - Real(b.min.x), y = Real(b.max.y) - Real(b.min.y), z = Real(b.max.z) - Real(b.min.z);
    return x * y + y * z + z * x;
}

/// `cbounds` grown by the centroids of [first, last).
inline Aabb grow_centroid_bounds(Aabb cbounds, const SahItem* first, const SahItem* last) {
    for (; first != last; ++first)
        cbounds.min = rcb::min(cbounds.min, first->centroid), cbounds.max = rcb::max(cbounds.max, first->centroid);
    return cbounds;
}

/// The border a sweep chose: the items of the bins below `bin` on `axis` go left, `left` of them.
struct SahSplit {
    int axis = -1;  // -1: no border leaves items on both sides
    int bin = 0;
    std::uint32_t left = 0;
    bool found() const { return axis >= 0; }
};

/// The bins of one split and the sweep over them. The bins are kept between splits (a member of
/// the builder), so that a node does not allocate them again.
template <class Real>
class BinnedSah {
public:
    /// The most bins per axis (the builders' `bins` parameters range up to it).
    static constexpr int kMaxBins = 256;
    struct Bin {
        Aabb box;
        std::uint32_t n;
    };

    /// Empties `bins` bins per axis over the centroid bounds `cbounds`. An axis whose centroids
    /// spread is binned (its scale is nonzero); returns whether any axis spreads (false: every
    /// centroid coincides, and no border can split).
    bool begin(const Aabb& cbounds, int bins) {
        bins_ = bins;
        lo_ = cbounds.min;
        bool any = false;
        for (int a = 0; a < 3; ++a) {
            const Real ext = Real(cbounds.max[a]) - Real(cbounds.min[a]);
            scale_[a] = ext > 0 ? Real(bins) / ext : Real(0);
            any = any || ext > 0;
        }
        bin_.assign(3 * std::size_t(bins), Bin{Aabb::empty(), 0});
        return any;
    }
    bool binned(int axis) const { return scale_[axis] != 0; }
    int bins() const { return bins_; }

    /// The bin of centroid `c` on `axis` (binned).
    int bin_of(const Vec3& c, int axis) const {
        return std::min(bins_ - 1, int((Real(c[axis]) - Real(lo_[axis])) * scale_[axis]));
    }
    /// Whether `item` goes left of `split`.
    bool goes_left(const SahItem& item, const SahSplit& split) const {
        return bin_of(item.centroid, split.axis) < split.bin;
    }

    /// Adds the items [first, last) to the bins of every binned axis.
    void add(const SahItem* first, const SahItem* last) {
        // Locals: the bins' stores could alias the members for the compiler.
        const int bins = bins_;
        const Real lo[3] = {Real(lo_[0]), Real(lo_[1]), Real(lo_[2])};
        const Real scale[3] = {scale_[0], scale_[1], scale_[2]};
        Bin* const bin = bin_.data();
        for (; first != last; ++first) {
            for (int a = 0; a < 3; ++a) {
                if (scale[a] == 0) continue;
                Bin& x = bin[a * bins + std::min(bins - 1, int((Real(first->centroid[a]) - lo[a]) * scale[a]))];
                x.box = merge(x.box, first->box);
                ++x.n;
            }
        }
    }

    /// The cheapest border of the binned axes for the `n` items added, or none (found() false)
    /// when no border leaves items on both sides. The costs start below the largest finite
    /// `Real`: a border whose cost overflows is never taken.
    SahSplit choose(std::uint32_t n) const {
        std::array<Real, kMaxBins> right;  // the right side's cost above each border
        SahSplit best;
        Real best_cost = std::numeric_limits<Real>::max();
        const int bins = bins_;
        for (int a = 0; a < 3; ++a) {
            if (scale_[a] == 0) continue;
            const Bin* bin = bin_.data() + std::size_t(a) * std::size_t(bins);
            Aabb acc = Aabb::empty();
            std::uint32_t m = 0;
            for (int k = bins - 1; k > 0; --k) {
                acc = merge(acc, bin[k].box), m += bin[k].n;
                right[std::size_t(k)] = m ? sah_area<Real>(acc) * Real(m) : Real(0);
            }
            acc = Aabb::empty(), m = 0;
            for (int k = 0; k < bins - 1; ++k) {
                acc = merge(acc, bin[k].box), m += bin[k].n;
                if (m == 0 || m == n) continue;
                const Real cost = sah_area<Real>(acc) * Real(m) + right[std::size_t(k) + 1];
                if (cost < best_cost) best_cost = cost, best = SahSplit{a, k + 1, m};
            }
        }
        return best;
    }

    /// The two sides' boxes of `split`: the unions of their bins.
    std::pair<Aabb, Aabb> sides(const SahSplit& split) const {
        Aabb left = Aabb::empty(), right = Aabb::empty();
        const Bin* bin = bin_.data() + std::size_t(split.axis) * std::size_t(bins_);
        for (int k = 0; k < bins_; ++k)
            (k < split.bin ? left : right) = merge(k < split.bin ? left : right, bin[k].box);
        return {left, right};
    }

    std::size_t memory_bytes() const { return bin_.capacity() * sizeof(Bin); }

private:
    std::vector<Bin> bin_;  // bins_ per axis, axis after axis
    int bins_ = 0;
    Vec3 lo_;
    Real scale_[3] = {0, 0, 0};  // bins per unit of centroid (0: the axis is not binned)
};

/// Moves the items of [first, last) that go left of `split` before the others (std::partition);
/// returns the first of the right side.
template <class Real>
SahItem* sah_partition(const BinnedSah<Real>& sah, const SahSplit& split, SahItem* first, SahItem* last) {
    return std::partition(first, last, [&](const SahItem& it) { return sah.goes_left(it, split); });
}

/// The partition of items[begin, begin + split.left) against the rest in steps: the items of the
/// left side's bins end in the first split.left places, each right-side item found there swapped
/// with the next left-side item from a second cursor beyond them. Resumable at any item.
class SahPartition {
public:
    void begin(std::uint32_t first, const SahSplit& split) {
        i_ = first, j_ = first + split.left, mid_ = first + split.left;
    }
    /// At most `budget` items of `items` (the whole array) looked at; returns how many.
    template <class Real>
    std::uint64_t step(const BinnedSah<Real>& sah, const SahSplit& split, SahItem* items, std::uint64_t budget) {
        std::uint32_t i = i_, j = j_;
        std::uint64_t done = 0;
        for (; done < budget && i < mid_; ++done) {
            if (sah.goes_left(items[i], split)) {
                ++i;
            } else {
                if (sah.goes_left(items[j], split)) std::swap(items[i], items[j]), ++i;
                ++j;
            }
        }
        i_ = i, j_ = j;
        return done;
    }
    bool done() const { return i_ >= mid_; }

private:
    std::uint32_t i_ = 0, j_ = 0, mid_ = 0;
};

/// Splits items[0, n) at n / 2 by size: the smaller boxes (by `Real` area) first, ties by id, so that
/// each side holds boxes of similar size (boxes nested around one centre: a side of large boxes
/// then shares a large common box) instead of an arbitrary half of all sizes. Returns n / 2.
template <class Real>
std::uint32_t split_by_size(SahItem* items, std::uint32_t n) {
    const std::uint32_t half = n / 2;
    std::nth_element(items, items + half, items + n, [](const SahItem& x, const SahItem& y) {
        const Real ax = sah_area<Real>(x.box), ay = sah_area<Real>(y.box);
        return ax < ay || (ax == ay && x.id < y.id);
    });
    return half;
}

/// Splits items[0, n) at n / 2 on the widest axis of the centroid bounds `cbounds` (in double),
/// ties by id. Returns n / 2.
inline std::uint32_t split_at_median(SahItem* items, std::uint32_t n, const Aabb& cbounds) {
    int axis = 0;
    for (int a = 1; a < 3; ++a)
        if (double(cbounds.max[a]) - double(cbounds.min[a]) > double(cbounds.max[axis]) - double(cbounds.min[axis]))
            axis = a;
    const std::uint32_t half = n / 2;
    std::nth_element(items, items + half, items + n, [axis](const SahItem& x, const SahItem& y) {
        return x.centroid[axis] < y.centroid[axis] || (x.centroid[axis] == y.centroid[axis] && x.id < y.id);
    });
    return half;
}

}  // namespace rcb
