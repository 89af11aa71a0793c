#pragma once
/// Dynamic BVH (thesis §4.4), after Catto's incremental tree as in Box2D v3: insertion picks the
/// sibling by SAH with branch and bound and refits (optionally rotating) the ancestors; a move
/// inside the leaf's fat box changes nothing in the tree. Rays test the object's own box at the
/// leaf, never the fat box, so hits stay exact (bvh_traversal.h). `mode = rebuild` is the
/// thesis' Table 6.4 "full SAH" variant (binned SAH, Wald 2007). SAH, height and crowd guards keep
/// the tree's cost bounded under churn and nested objects. docs/structures.md has the details.

#include <bit>
#include <cstdint>
#include <string>
#include <tuple>
#include <unordered_map>
#include <vector>

#include "accel/interface/params.h"
#include "accel/interface/structure.h"
#include "accel/bvh/binned_sah.h"
#include "accel/bvh/bvh_traversal.h"
#include "accel/common/query_scratch.h"

namespace rcb {

class DynamicBvh : public StructureBase<DynamicBvh, StackScratch> {
public:
    /// Params::mode, parsed once by the constructor; the enumerators follow kModeChoices.
    enum class Mode : std::uint8_t { incremental, rebuild };
    static constexpr const char* kModeChoices = "incremental,rebuild";

    struct Params {
        /// Leaf boxes are enlarged on every side by this fraction of the object's longest edge.
        double margin = 0.1;
        /// Tree rotations on the refit path (Box2D v3 b_RotateNodes).
        bool rotate = true;
        /// "incremental": Catto insertion only; "rebuild": full binned-SAH builds (the top of this file).
        std::string mode = "incremental";
        /// rebuild mode: rebuild at commit every this many frames (0: never by count).
        int rebuild_every = 1;
        /// rebuild mode: rebuild when sah_cost > this × the cost after the last build (0: never).
        double rebuild_growth = 0.0;
        /// rebuild mode: SAH bins per axis of the top-down build.
        int bins = 16;
        /// incremental mode: rebuild when the SAH cost grew by this factor (0: off; "SAH guard" in
        /// docs/structures.md, Dynamic BVH).
        double sah_guard = 2.0;
        /// Scan the leaves of a crowd whose common box the segment meets ("Crowd guard" in
        /// docs/structures.md, Dynamic BVH).
        bool crowd_guard = true;
        /// incremental mode: binned-SAH rebuild when the height exceeds height_limit(size).
        bool height_guard = true;
        int cast_threads = 1;

        static constexpr auto fields() {
            return std::tuple{
                Field{"margin", &Params::margin, 0.0, 4.0, "fat-box margin, × the object's longest edge per side"},
                Field{"rotate", &Params::rotate, 0, 1, "tree rotations on the refit path (Box2D v3)"},
                Field{"mode", &Params::mode, 0, 0, "incremental insertion, or full binned-SAH rebuilds",
                      choices(kModeChoices)},
                Field{"rebuild_every", &Params::rebuild_every, 0, 1000000,
                      "rebuild mode: full rebuild every k frames (0: never by count)", kLogScale},
                Field{"rebuild_growth", &Params::rebuild_growth, 0.0, 100.0,
                      "rebuild mode: full rebuild when the SAH cost grew by this factor (0: never)"},
                Field{"bins", &Params::bins, 2, 256, "rebuild mode: SAH bins per axis", kLogScale},
                Field{"sah_guard", &Params::sah_guard, 0.0, 100.0,
                      "incremental mode: binned-SAH rebuild when the SAH cost grew by this factor since the last "
                      "build, checked every max(64, size/8) changes (0: off)",
                      kNotTuned},
                Field{"crowd_guard", &Params::crowd_guard, 0.0, 1.0,
                      "a segment meeting the common box of a subtree of at least 16 boxes that share a point tests "
                      "its leaves in order instead of descending (exact either way)",
                      kNotTuned},
                Field{"height_guard", &Params::height_guard, 0.0, 1.0,
                      "incremental mode: binned-SAH rebuild when the height exceeds 4 bit_width(size) + 8", kNotTuned},
                cast_threads_field<Params>()};
        }
    };

    /// Leaves below an inner node for it to be a crowd.
    static constexpr std::uint32_t kCrowdLeaves = 16;
    /// The height guard's limit for a tree of `size` leaves.
    static int height_limit(std::size_t size) { return 4 * int(std::bit_width(size)) + 8; }

    DynamicBvh();
    explicit DynamicBvh(const Params& p);

    void build(std::span<const Object> objects) override;
    void insert(const Object& object) override;
    void remove(Uid uid) override;
    void move(const Object& object) override;
    void commit() override;
    std::size_t size() const override { return leaf_of_.size(); }
    std::uint64_t writes() const override { return writes_; }
    std::size_t memory_bytes() const override;
    nlohmann::json stats() const override;
    void check() const override;

    // The traversal interface of StructureBase: the deferred rebuild and crowd search, then const
    // traversals with a stack per thread.
    void prepare() {
        if (dirty_) rebuild();
        if (crowds_dirty_) find_crowds();
    }
    void fit(StackScratch& scratch) const {
        scratch.fit(root_ == kNullNode ? 2u : 2 * (std::size_t(nodes_[root_].height) + 2u));
    }
    template <class Count, class Visit>
    void traverse(const Segment& s, Count& count, Visit&& visit, StackScratch& scratch) const {
        traverse_bvh(*this, root_, scratch.stack(), s, count, visit);
    }

    /// The SAH cost of the tree (thesis eq. 3.2, C_T = C_I = 1; leaves with their fat boxes).
    double sah_cost() const;
    int height() const { return root_ == kNullNode ? -1 : nodes_[root_].height; }

    // The tree interface of traverse_bvh.
    bool is_leaf(std::uint32_t n) const { return nodes_[n].height == 0; }
    const Aabb& node_box(std::uint32_t n) const { return nodes_[n].box; }
    std::uint32_t child(std::uint32_t n, int k) const { return nodes_[n].child[k]; }
    const Aabb& object_box(std::uint32_t n) const { return tight_[n]; }
    const Aabb& leaf_box(std::uint32_t n) const { return nodes_[n].box; }
    Uid leaf_uid(std::uint32_t n) const { return nodes_[n].child[0]; }
    bool has_crowds() const { return !crowds_.empty(); }
    bool is_crowd(std::uint32_t n) const { return crowd_of_[n] != kNullNode; }
    template <class Count, class Visit>
    CrowdScan scan_crowd(std::uint32_t n, const SegmentSlabs& slabs, Count& count, Visit& visit) const {
        const Crowd& c = crowds_[crowd_of_[n]];
        float t_near, t_far;
        count.reads(&c, sizeof c);
        if (!slabs.clip(c.common, t_near, t_far)) return CrowdScan::descend;
        // Every box below holds the common box; each is still tested, for its entry parameter and
        // so that the answer never rests on this shortcut.
        count.box_tests(c.last - c.first + 1);
        for (std::uint32_t k = c.first; k <= c.last; ++k) {
            count.reads(&packed_[k], sizeof packed_[k]);
            if (!slabs.clip(packed_[k].box, t_near, t_far)) continue;
            count.hits();
            if (!visit(packed_[k].uid, t_near)) return CrowdScan::stop;
        }
        return CrowdScan::done;
    }

private:
    struct Node {
        Aabb box;                // 24 B: the fat box for a leaf, the union of the children otherwise
        std::uint32_t parent;    // 4 B: kNullNode at the root
        std::uint32_t child[2];  // 8 B: a leaf keeps its uid in child[0]; a free node its successor
        std::int32_t height;     // 4 B: 0 leaf, -1 free, else 1 + max(children)
    };
    static_assert(sizeof(Node) == 40);

    std::uint32_t allocate();
    void release(std::uint32_t n);
    Aabb fat_box(const Aabb& box) const;
    std::uint32_t make_leaf(const Object& o);
    void insert_leaf(std::uint32_t leaf);
    void remove_leaf(std::uint32_t leaf);
    std::uint32_t find_best_sibling(const Aabb& box) const;
    void refit_from(std::uint32_t n);
    void rotate_nodes(std::uint32_t a);
    void rebuild();
    /// The top-down build over leaves: their fat boxes, centres and node ids copied out of the node
    /// array (SahItem::id is the node), so that binning and partitioning read memory in order.
    std::uint32_t build_range(SahItem* items, std::uint32_t count);
    bool deferring() const { return dirty_; }

    Params params_;
    Mode mode_ = Mode::incremental;
    std::vector<Node> nodes_;
    std::vector<Aabb> tight_;  // per node: the object's own box (leaves only)
    std::uint32_t root_ = kNullNode;
    std::uint32_t free_ = kNullNode;
    std::uint32_t free_count_ = 0;
    std::unordered_map<Uid, std::uint32_t> leaf_of_;
    /// writes(): one per node written in one step (made, freed, linked, refitted, rotated, built; a
    /// leaf's own box counts too) and per crowd entry packed: the tree memory an update stores to.
    std::uint64_t writes_ = 0;
    // Rebuild mode.
    bool dirty_ = false;  // leaves changed, tree to be rebuilt at commit
    std::uint32_t frames_since_build_ = 0;
    double cost_after_build_ = 0.0;
    std::vector<SahItem> build_items_;
    BinnedSah<float> sah_;
    // SAH guard (incremental mode).
    std::size_t changes_since_check_ = 0;
    double guard_baseline_ = 0.0;
    std::uint32_t guard_rebuilds_ = 0;
    std::uint32_t height_rebuilds_ = 0;
    void check_sah_guard();
    // Crowd guard ("Crowd guard" in docs/structures.md, Dynamic BVH): per node its crowd
    // (kNullNode: none), the crowds, the leaves packed in depth-first order; empty while the tree
    // has no crowds.
    struct Crowd {
        Aabb common;
        std::uint32_t first, last;  // the run of packed leaves below
        friend bool operator==(const Crowd&, const Crowd&) = default;
    };
    struct PackedLeaf {
        Aabb box;
        Uid uid;
        friend bool operator==(const PackedLeaf&, const PackedLeaf&) = default;
    };
    std::vector<std::uint32_t> crowd_of_;
    std::vector<Crowd> crowds_;
    std::vector<PackedLeaf> packed_;
    bool crowds_dirty_ = false;  // the tree has crowds and changed since they were found
    std::size_t changes_since_crowd_check_ = 0;
    /// Finds the crowds (and packs the leaves) afresh; frees everything when there are none.
    void find_crowds();
    /// find_crowds() if a cheaper walk over the fat boxes finds candidates, else frees everything.
    void look_for_crowds();
    /// The walk of both: the crowd nodes into `found` (and, with `tight`, their runs and common
    /// boxes into crowds_); whether there are any.
    bool walk_crowds(bool tight, std::vector<std::uint32_t>& found);
    /// The tree changed: crowds are found again before the next query, if there were any.
    void touch() {
        ++changes_since_crowd_check_;
        if (!crowds_.empty()) crowds_dirty_ = true;
    }
};

}  // namespace rcb
