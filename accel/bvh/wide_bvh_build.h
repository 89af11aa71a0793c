#pragma once
/// The wide BVH's top-down build (wide_bvh.h): binned SAH (binned_sah.h, Wald 2007) in double,
/// straight into wide nodes, splitting the part with the largest box until the node holds `width`
/// parts (Wald et al. 2008's collapse of a binary SAH tree into wide nodes, done while building).
/// Resumable, so that a progressive rebuild (wide_bvh_rebuild.h) can spread it over commits.

#include <array>
#include <cstdint>
#include <vector>

#include "accel/bvh/binned_sah.h"
#include "core/base/geometry.h"

namespace rcb {

class WideBvh;

/// Lanes per wide node: children of an inner node, objects of a leaf (WideBvh::kLanes).
inline constexpr int kWideLanes = 8;

/// The top-down binned SAH build of one tree, resumable: step() does at most about `budget` units
/// of work (one unit: an item binned, bounded or partitioned, an object written to a leaf) and
/// returns what it did; WideBvh's build() and rebuild() run it without a limit, a progressive
/// rebuild a share per commit. Depth first: pending_ holds the blocks still to build, and the node
/// being opened keeps its parts and the split in progress between steps. The tree passed to each
/// call is the one it builds (its owner). The items' ids are uids.
class WideBvhBuilder {
public:
    /// The centre of `b` without overflow near the coordinate limit: the items' centroids.
    static Vec3 centroid(const Aabb& b) { return b.min * 0.5f + b.max * 0.5f; }

    /// The objects to build from: filled before begin(), freed by end().
    std::vector<SahItem>& items() { return items_; }
    const std::vector<SahItem>& items() const { return items_; }
    /// Empties `t` and starts a build of items().
    void begin(WideBvh& t);
    std::uint64_t step(WideBvh& t, std::uint64_t budget);
    bool done() const { return pending_.empty() && !opening_; }
    void end(WideBvh& t);
    /// Units of the build so far.
    std::uint64_t work() const { return build_work_; }
    /// Splits items [0, n) in two (binned SAH over `bins` bins; by size or the median when that
    /// cannot split) and returns the size of the first part, in 1..n-1. For the nine objects of a
    /// leaf split; no build is in progress then (builds run to their end, or in the next tree).
    std::uint32_t split(int bins, SahItem* items, std::uint32_t n);
    std::size_t memory_bytes() const;

private:
    static constexpr std::uint32_t kNone = 0xffffffffu;
    /// Items [begin, begin + n) of items_ and their box (the union of the items' boxes).
    struct Range {
        std::uint32_t begin = 0, n = 0;
        Aabb box = Aabb::empty();
    };
    /// A block still to build: a range below lane `lane` of `parent` (kNone: the root).
    struct Pending {
        Range range;
        std::uint32_t parent = kNone;
        std::uint16_t depth = 0;
        std::uint8_t lane = 0;
    };
    /// The stage of the split of parts_[splitting_].
    enum class Stage : std::uint8_t { centroid_bounds, binning, partition };

    /// Starts the split of parts_[part].
    void start_split(int part);
    /// One step of the split of parts_[splitting_]: centroid bounds, binning, then the
    /// partition.
    std::uint64_t split_step(int bins, std::uint64_t budget);
    /// The fallbacks when binning cannot split the part: by size when its centroids coincide,
    /// else at the median of the widest axis. Done whole (these parts are rare, and small in
    /// practice).
    void split_fallback();
    /// parts_[splitting_] split after its first `left` items into parts with these boxes.
    void divide(std::uint32_t left, const Aabb& left_box, const Aabb& right_box);
    /// The node being opened is complete: its block, its lanes, its parts pending as children.
    void finish_node(WideBvh& t);
    void make_leaf(WideBvh& t, const Pending& p);

    std::vector<SahItem> items_;
    std::vector<Pending> pending_;
    bool opening_ = false;  // a node is being opened: open_, parts_, splitting_ hold it
    Pending open_;          // the node being opened
    std::array<Range, kWideLanes> parts_;
    int nparts_ = 0;
    int splitting_ = -1;  // the part being split, or -1
    Stage stage_ = Stage::centroid_bounds;
    std::uint32_t cursor_ = 0;      // the next item of the stage
    Aabb cbox_;                     // the centroid bounds of the part being split
    BinnedSah<double> sah_;         // its bins
    SahSplit split_;                // the chosen split
    SahPartition partition_;        // the partition in progress
    std::uint64_t build_work_ = 0;  // units of the build so far
};

}  // namespace rcb
