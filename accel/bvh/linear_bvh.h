#pragma once
/// Linear BVH (thesis §4.5, after Karras 2012), rebuilt at every commit: Morton codes of the
/// centroids (21 bits per axis), a stable most-significant-digit radix sort (or, when few objects
/// changed, a merge of the keys that left the last rebuild's order back into it: the same order),
/// and Karras' radix tree (thesis Algorithm 3) with its bounds (thesis Algorithm 4) in one
/// bottom-up pass after Apetrei 2014; `threads` runs the steps in a TBB arena and every step is
/// deterministic, so the tree does not depend on the thread count. An
/// outlier trim (common/outlier_trim.h), size-ordered ties of equal codes and crowd scans keep it
/// fast on hostile scenes; answers are exact either way. docs/structures.md has the details.

#include <algorithm>
#include <array>
#include <cstdint>
#include <memory>
#include <tuple>
#include <vector>

#include "accel/interface/params.h"
#include "accel/common/slot_boxes.h"
#include "accel/interface/structure.h"
#include "accel/bvh/bvh_traversal.h"
#include "accel/common/query_scratch.h"

namespace rcb {

class LinearBvh : public StructureBase<LinearBvh, StackScratch> {
public:
    /// The most build threads (Params::threads' range).
    static constexpr int kMaxThreads = 64;
    /// Chunks of the keys per build thread: the unit the steps split the work into.
    static constexpr std::size_t kChunksPerThread = 4;
    /// The most chunks of a rebuild: the size of the per-chunk arrays on the build's stack.
    static constexpr std::size_t kMaxChunks = std::size_t(kMaxThreads) * kChunksPerThread;

    struct Params {
        /// Threads of the build (1 or 2 on this machine; the tree does not depend on it).
        int threads = 1;
        /// Morton codes over the central 99% of the centroids when the full centroid bounds are more
        /// than 8× larger ("Outlier guard" in docs/structures.md, Linear BVH).
        bool outlier_guard = true;
        /// Scan the leaves of a crowd whose common box the segment meets ("Crowds" in
        /// docs/structures.md, Linear BVH).
        bool crowd_guard = true;
        /// Threads of the timed ray batch (`threads` is the build's; see docs/structures.md).
        int cast_threads = 1;
        /// Sort from the last rebuild's order when few objects changed (the same tree either way).
        bool coherent_sort = true;
        static constexpr auto fields() {
            return std::tuple{
                Field{"threads", &Params::threads, 1, kMaxThreads, "build threads (TBB task arena)", kNotTuned},
                Field{"outlier_guard", &Params::outlier_guard, 0.0, 1.0,
                      "Morton codes over the central 99% of the centroids when the full centroid bounds "
                      "are over 8x larger (exact either way)",
                      kNotTuned},
                Field{"coherent_sort", &Params::coherent_sort, 0.0, 1.0,
                      "sort from the last rebuild's order when at most 1/16 of the objects changed (the "
                      "same tree either way)",
                      kNotTunedDefaultUnrecorded},
                cast_threads_field<Params>(),
                Field{"crowd_guard", &Params::crowd_guard, 0.0, 1.0,
                      "a segment meeting the common box of a subtree of at least 16 boxes that share a "
                      "point tests its leaves in order instead of descending (exact either way)",
                      kNotTuned}};
        }
    };
    /// Leaves below an inner node for it to be a crowd.
    static constexpr std::uint32_t kCrowdLeaves = 16;
    /// A tree without crowds is followed by this many rebuilds before crowds are looked for again.
    static constexpr std::uint32_t kCrowdCheckEvery = 8;
    /// Inner node flags: the node is a crowd; the boxes below share a point (then common_ holds
    /// their intersection; a leaf always counts as shared).
    static constexpr std::uint8_t kCrowd = 1, kShared = 2;

    /// 32 bytes, aligned: two to a cache line, none across two. It holds what the traversal reads;
    /// what only the build and check() need (height, flags) is kept per inner node in Meta.
    struct alignas(32) Node {
        Aabb box;                // 24 B
        std::uint32_t child[2];  // 8 B: a leaf keeps its uid in child[0], kNullNode in child[1]
        friend bool operator==(const Node&, const Node&) = default;
    };
    static_assert(sizeof(Node) == 32);
    struct Meta {
        std::uint8_t height;  // at least 1 (leaves have 0); at most 97: codes and indices have 96 bits
        std::uint8_t flags;   // kCrowd, kShared
        friend bool operator==(const Meta&, const Meta&) = default;
    };

    LinearBvh();
    explicit LinearBvh(const Params& p);
    ~LinearBvh() override;

    void build(std::span<const Object> objects) override;
    void insert(const Object& object) override;
    void remove(Uid uid) override;
    void move(const Object& object) override;
    void commit() override;
    std::size_t size() const override { return objects_.size(); }
    std::uint64_t writes() const override { return writes_; }
    std::uint64_t update_work() const override { return update_work_; }
    std::size_t memory_bytes() const override;
    nlohmann::json stats() const override;
    void check() const override;

    // The traversal interface of StructureBase: the deferred rebuild, then const traversals with a
    // stack per thread.
    void prepare() {
        if (dirty_) rebuild();
    }
    void fit(StackScratch& scratch) const { scratch.fit(2 * (std::size_t(std::max(height(), 0)) + 2u)); }
    template <class Count, class Visit>
    void traverse(const Segment& s, Count& count, Visit&& visit, StackScratch& scratch) const {
        traverse_bvh(*this, root(), scratch.stack(), s, count, visit);
    }

    /// The SAH cost of the tree (thesis eq. 3.2, C_T = C_I = 1).
    double sah_cost() const;
    int height() const { return meta_.empty() ? int(nodes_.size()) - 1 : meta_[0].height; }
    /// The node array (for tests: identical for every thread count).
    const std::vector<Node>& nodes() const { return nodes_; }
    /// Height and flags of the inner nodes (for tests: identical for every thread count).
    const std::vector<Meta>& meta() const { return meta_; }
    /// The sorted Morton codes of the last rebuild (for tests).
    const std::vector<std::uint64_t>& codes() const { return codes_; }
    /// Wall time of the last rebuild's steps in milliseconds (bench/lbvh_build.cpp prints them).
    struct Phases {
        double codes = 0;  ///< centroid bounds, outlier trim, Morton codes (resort(): and the leaf records)
        double sort = 0;   ///< radix sort and the size order of equal codes (resort(): the split and merge)
        double tree = 0;   ///< leaves (resort(): written by the merge), inner nodes and their bounds
    };
    const Phases& last_phases() const { return phases_; }
    /// Whether the last rebuild sorted from the previous order (resort(); for tests and benches).
    bool last_resorted() const { return resorted_; }

    // The tree interface of traverse_bvh.
    bool is_leaf(std::uint32_t n) const { return n >= leaf_base_; }
    const Aabb& node_box(std::uint32_t n) const { return nodes_[n].box; }
    std::uint32_t child(std::uint32_t n, int k) const { return nodes_[n].child[k]; }
    const Aabb& object_box(std::uint32_t n) const { return nodes_[n].box; }
    const Aabb& leaf_box(std::uint32_t n) const { return nodes_[n].box; }
    Uid leaf_uid(std::uint32_t n) const { return nodes_[n].child[0]; }
    bool has_crowds() const { return crowds_ != 0; }
    bool is_crowd(std::uint32_t n) const { return meta_[n].flags & kCrowd; }
    template <class Count, class Visit>
    CrowdScan scan_crowd(std::uint32_t n, const SegmentSlabs& slabs, Count& count, Visit& visit) const {
        float t_near, t_far;
        count.reads(&common_[n], sizeof(Aabb));
        if (!slabs.clip(common_[n], t_near, t_far)) return CrowdScan::descend;
        // Every box below holds the common box, so the segment meets all of them; each is still
        // tested, for its entry parameter and so that the answer never rests on this shortcut.
        const std::uint32_t first = leaf_base_ + ranges_[n][0], last = leaf_base_ + ranges_[n][1];
        count.box_tests(last - first + 1);
        for (std::uint32_t leaf = first; leaf <= last; ++leaf) {
            count.reads(&nodes_[leaf].box, sizeof(Aabb));
            if (!slabs.clip(nodes_[leaf].box, t_near, t_far)) continue;
            count.hits();
            if (!visit(nodes_[leaf].child[0], t_near)) return CrowdScan::stop;
        }
        return CrowdScan::done;
    }

private:
    std::uint32_t root() const { return nodes_.empty() ? kNullNode : 0u; }
    void rebuild();
    // The rebuild's steps (the top of this file): the radix path's codes, the tree; resort()'s
    // bounds and codes, and its split, sort and merge (Resort).
    std::uint64_t encode(std::size_t chunks, bool bounds_known);
    void build_tree(std::size_t chunks, bool leaves_written);
    Aabb resort_bounds(std::size_t chunks);
    void resort_codes(std::size_t chunks, const Aabb& cb);
    struct Resort;
    struct Climb;
    template <class F>
    void parallel(std::size_t n, std::size_t grain, F&& f);
    void sort_codes(std::uint64_t varying);
    void trim_outliers(Aabb& centroid_bounds);
    void order_equal_codes(std::size_t chunks);
    template <class Lap>
    bool resort(std::size_t chunks, Lap& lap, bool& bounds_known);

    Params params_;
    struct Arena;
    std::unique_ptr<Arena> arena_;
    // The objects, dense (swap-remove).
    SlotBoxes objects_;
    bool dirty_ = false;
    // The tree and the build's scratch (kept between builds: no allocation once sized).
    std::vector<Node> nodes_;
    std::vector<Meta> meta_;
    std::uint32_t leaf_base_ = 0;
    std::vector<std::uint64_t> codes_, codes_tmp_;
    std::vector<std::uint32_t> order_, order_tmp_;
    std::vector<std::uint32_t> histograms_, bucket_start_;
    // Per split of the sorted keys: the far end of the first child to finish; kNullNode before
    // and again after the build (the second child resets it: no clearing pass).
    std::vector<std::uint32_t> bound_;
    // resort(): changes since the last rebuild (kNoOrder after build()), per chunk the kept
    // positions, and the positions out of order, per chunk and all.
    static constexpr std::size_t kNoOrder = std::size_t(-1) / 2;
    std::size_t changes_ = kNoOrder;
    // The full centroid bounds of the last rebuild (before the outlier trim), and whether a change
    // since may have moved them (insert()).
    Aabb centroid_bounds_ = Aabb::empty();
    bool centroids_moved_ = true;
    bool resorted_ = false;
    std::vector<std::uint32_t> kept_;
    std::vector<std::vector<std::uint32_t>> outliers_;
    std::vector<std::uint32_t> outliers_all_;
    // Per chunk of leaves: the nodes [l, r] whose climb stopped at the chunk's edge.
    std::vector<std::vector<std::array<std::uint32_t, 2>>> pending_;
    // Per inner node: the intersection of the boxes below (where kShared); per crowd: its first
    // and last leaf.
    std::vector<Aabb> common_;
    std::vector<std::array<std::uint32_t, 2>> ranges_;
    // Guard reports (stats): nodes that are crowds, objects in runs of equal codes, outliers trimmed.
    std::size_t crowds_ = 0;
    std::size_t tied_codes_ = 0;
    bool trimmed_ = false;
    // The bounds the last codes were normalised to (the first guess for the next rebuild's).
    Aabb code_bounds_ = Aabb::empty();
    Phases phases_;
    // Crowds are looked for in this tree ("Crowds" in docs/structures.md, Linear BVH), and
    // rebuilds since they last were.
    bool crowds_checked_ = false;
    std::uint32_t rebuilds_since_crowd_check_ = 0;
    /// writes(): per rebuild, one per node of the new tree (2n − 1), per sorted Morton code (n) and,
    /// when sorting from the last order, per leaf record staged (n). Changes only mark the tree dirty.
    std::uint64_t writes_ = 0;
    /// update_work(): per rebuild, the keys the radix sort placed (n), or on the merge from the last
    /// order (resort()) the keys out of that order, which it sorts apart: what tells a rebuild that
    /// sorted from one that merged, whose writes are alike (both write every code, leaf and node).
    std::uint64_t update_work_ = 0;
};

}  // namespace rcb
