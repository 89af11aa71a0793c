#pragma once
/// The wide BVH's top-down build (wide_bvh.h): a binary tree by binned SAH (binned_sah.h, Wald 2007)
/// in double, down to parts of `leaf_size` objects, then collapsed into wide nodes of up to `width`
/// children by dynamic programming over the binary tree (Ylitie, Karras & Laine 2017, "Efficient
/// incoherent ray traversal on GPUs through compressed wide BVHs": each subtree priced as a forest
/// of at most 1..width roots, bottom up, then the cheapest choices traced top down), which picks the
/// collapse of least SAH cost: the least expected inner-node visits, so inner nodes come out near
/// full. Resumable, so that a progressive rebuild (wide_bvh_rebuild.h) can spread it over commits.
///
/// A top-down split of a wide node's largest child until the node holds `width` children (Wald et
/// al. 2008; Embree's GeneralBVHBuilder::recurse in kernels/builders/bvh_builder_sah.h splits so),
/// closing a child as a leaf once it holds `leaf_size` objects or fewer, leaves a part of 9 to 16
/// objects as an inner node of two leaves below a parent with no lane to spare; the collapse pulls
/// such subtrees up into their parent wherever that saves visits.

#include <array>
#include <cstdint>
#include <vector>

#include "accel/bvh/binned_sah.h"
#include "core/base/geometry.h"

namespace rcb {

class WideBvh;

/// Lanes per wide node: children of an inner node, objects of a leaf (WideBvh::kLanes).
inline constexpr int kWideLanes = 8;

/// The build of one tree, resumable: step() does at most about `budget` units of work (one unit: an
/// item binned, bounded or partitioned, a binary node made or priced, a lane or an object written
/// to a block) and returns what it did; WideBvh's build() and rebuild() run it without a limit, a
/// progressive rebuild a share per commit. Three phases: the binary tree (depth first: pending_
/// holds the ranges still to split, and the split in progress keeps its state between steps), the
/// collapse's prices (binary nodes in reverse order of creation, children before their parent),
/// and the blocks (depth first from the root: emit_ holds the blocks still to write). The tree
/// passed to each call is the one it builds (its owner). The items' ids are uids.
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
    bool done() const { return phase_ == Phase::done; }
    void end(WideBvh& t);
    /// Units of the build so far.
    std::uint64_t work() const { return build_work_; }
    /// Splits items [0, n) in two (binned SAH over `bins` bins; by size or the median when that
    /// cannot split) and returns the size of the first part, in 1..n-1. For the nine objects of a
    /// leaf split; no build is in progress then (builds run to their end, or in the next tree).
    std::uint32_t split(int bins, SahItem* items, std::uint32_t n);
    std::size_t memory_bytes() const;

    /// The mean children per inner block of a tree (WideBvh::stats() reports it as `inner_fill`,
    /// which the collapse raises); 0 without inner blocks.
    static double inner_fill(const WideBvh& t);

private:
    static constexpr std::uint32_t kNone = 0xffffffffu;
    /// Items [begin, begin + n) of items_ and their box (the union of the items' boxes).
    struct Range {
        std::uint32_t begin = 0, n = 0;
        Aabb box = Aabb::empty();
    };
    /// A node of the binary tree: its items, and its right child (its left child is the next node;
    /// none: a leaf, of at most leaf_split_ objects).
    struct Node {
        Range range;
        std::uint32_t right = kNone;
        bool leaf() const { return right == kNone; }
    };
    /// A range still to split, below side `side` of binary node `parent` (kNone: the root).
    struct Pending {
        Range range;
        std::uint32_t parent = kNone;
        std::uint8_t side = 0;
    };
    /// A block still to write: binary node `node` below lane `lane` of block `parent` (kNone: the
    /// root).
    struct Emit {
        std::uint32_t node = 0, parent = kNone;
        std::uint16_t depth = 0;
        std::uint8_t lane = 0;
    };
    enum class Phase : std::uint8_t { binary, price, emit, done };
    /// The stage of the split of parts_[splitting_].
    enum class Stage : std::uint8_t { centroid_bounds, binning, partition };

    /// Steps of each phase, within `budget`.
    std::uint64_t binary_step(int bins, std::uint64_t budget);
    std::uint64_t price_step(int width, std::uint64_t budget);
    std::uint64_t emit_step(WideBvh& t, std::uint64_t budget);
    /// The collapse's prices of binary node `i`, its children's on top of prices_: for j = 1..width
    /// the least cost of its subtree as a forest of at most j roots, replacing theirs; pick_[i·width
    /// + j − 1] the choice that gives it: for j = 1 0 when a leaf, else the roots of the left
    /// child; for j > 1 0 when fewer roots, else the roots the left child takes.
    void price(std::uint32_t i, int width);
    /// The children of the wide node made from inner binary node `i`, in lane order; returns
    /// how many.
    int collapse(std::uint32_t i, int width, std::uint32_t* roots) const;
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
    /// Writes the block of `e`: a leaf of its items, or an inner block of its collapse's roots
    /// (pushed onto emit_); returns the units.
    std::uint64_t write_block(WideBvh& t, const Emit& e);

    std::vector<SahItem> items_;
    Phase phase_ = Phase::done;
    std::vector<Pending> pending_;          // the binary phase's ranges still to split
    std::vector<Node> nodes_;               // the binary tree, parents before children
    std::vector<double> prices_;            // `width` prices per priced node whose parent is not yet priced
    std::vector<std::uint8_t> pick_;        // per node, `width` choices (price())
    std::uint32_t leaf_size_ = 8;           // Params::leaf_size of the build
    std::uint32_t leaf_split_ = 4;          // the binary tree's leaves hold at most this many objects
    std::vector<Emit> emit_;                // the blocks still to write
    std::uint32_t splitting_node_ = kNone;  // the binary node whose range is being split
    std::uint32_t price_cursor_ = 0;        // the price phase's next node + 1
    std::array<Range, 2> parts_;
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
