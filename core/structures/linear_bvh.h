#pragma once
/// Linear BVH (thesis §4.5), after Karras 2012, "Maximizing parallelism in the construction of
/// BVHs, octrees, and k-d trees" (HPG 2012), rebuilt from scratch at every commit:
///  1. Morton codes of the object centroids, normalised to the bounds of the centroids: 63-bit
///     codes, 21 bits per axis (thesis §4.5.1).
///  2. A stable LSD radix sort of (code, slot) pairs, 11-bit digits, passes whose digit is the same
///     for every key skipped; equal codes stay in slot order.
///  3. The binary radix tree of Karras' Algorithm 3 (thesis Algorithm 3), one independent task per
///     inner node; equal codes are told apart by their sorted index (Karras §4: δ(i, j) falls back
///     to 64 + clz(i xor j)), so duplicates still give a valid tree.
///  4. Bounds bottom up with one atomic flag per inner node (thesis Algorithm 4): the second thread
///     to reach a node merges its children's boxes and goes on.
/// `threads` runs steps 1–4 in a tbb::task_arena of that many threads (1: plain loops, the thesis'
/// single-core setup). Every step is deterministic, so the tree is identical for every thread count.
///
/// Outlier guard (issue #9, `outlier_guard`, on by default): with one object 10^6 scene sizes away,
/// the Morton grid normalised to all centroids puts the rest of the scene into one code, and the
/// tree over equal codes splits by index, not by space. When the centroid bounds on an axis are
/// more than 8× the extent of the central 99% of the centroids (a strided sample of at most 4096),
/// the codes are normalised to that central part and the outliers clamp to its faces. Node boxes
/// still come from the objects' boxes, so answers are exact either way.
///
/// Node layout (Karras): inner nodes 0 … N−2 (root 0), leaves N−1 … 2N−2 in sorted order; a leaf's
/// box is the object's own box. There is no free list: the arrays are rebuilt, never patched.

#include <atomic>
#include <cstdint>
#include <memory>
#include <tuple>
#include <vector>

#include "core/params.h"
#include "core/slot_boxes.h"
#include "core/structure.h"
#include "core/structures/bvh_traversal.h"

namespace rcb {

class LinearBvh : public StructureBase<LinearBvh> {
public:
    struct Params {
        /// Threads of the build (1 or 2 on this machine; the tree does not depend on it).
        int threads = 1;
        /// Morton codes over the central 99% of the centroids when the full centroid bounds are more
        /// than 8× larger (see "Outlier guard" above).
        bool outlier_guard = true;
        static constexpr auto fields() {
            return std::tuple{Field{"threads", &Params::threads, 1, 64, "build threads (TBB task arena)", false},
                              Field{"outlier_guard", &Params::outlier_guard, 0.0, 1.0,
                                    "Morton codes over the central 99% of the centroids when the full centroid bounds "
                                    "are over 8x larger (exact either way)",
                                    false}};
        }
    };

    struct Node {
        Aabb box;                // 24 B
        std::uint32_t child[2];  // 8 B: a leaf keeps its uid in child[0]
        std::uint32_t parent;    // 4 B: kNullNode at the root
        std::int32_t height;     // 4 B: 0 for leaves
        friend bool operator==(const Node&, const Node&) = default;
    };
    static_assert(sizeof(Node) == 40);

    LinearBvh();
    explicit LinearBvh(const Params& p);
    ~LinearBvh() override;

    void build(std::span<const Object> objects) override;
    void insert(const Object& object) override;
    void remove(Uid uid) override;
    void move(const Object& object) override;
    void commit() override;
    std::size_t size() const override { return objects_.size(); }
    std::size_t memory_bytes() const override;
    nlohmann::json stats() const override;
    void validate() const override;

    template <class Count, class Visit>
    void traverse(const Segment& s, Count& count, Visit&& visit) {
        if (dirty_) rebuild();
        traverse_bvh(*this, root(), stack_.data(), s, count, visit);
    }

    /// The SAH cost of the tree (thesis eq. 3.2, C_T = C_I = 1).
    double sah_cost() const;
    int height() const { return nodes_.empty() ? -1 : nodes_[0].height; }
    /// The node array (for tests: identical for every thread count).
    const std::vector<Node>& nodes() const { return nodes_; }

    // The tree interface of traverse_bvh.
    bool is_leaf(std::uint32_t n) const { return n >= leaf_base_; }
    const Aabb& node_box(std::uint32_t n) const { return nodes_[n].box; }
    std::uint32_t child(std::uint32_t n, int k) const { return nodes_[n].child[k]; }
    const Aabb& object_box(std::uint32_t n) const { return nodes_[n].box; }
    Uid leaf_uid(std::uint32_t n) const { return nodes_[n].child[0]; }

private:
    std::uint32_t root() const { return nodes_.empty() ? kNullNode : 0u; }
    void rebuild();
    template <class F>
    void parallel(std::size_t n, std::size_t grain, F&& f);
    void radix_sort();
    void trim_outliers(Aabb& centroid_bounds) const;
    static constexpr double kOutlierStretch = 8.0;

    Params params_;
    struct Arena;
    std::unique_ptr<Arena> arena_;
    // The objects, dense (swap-remove).
    SlotBoxes objects_;
    bool dirty_ = false;
    // The tree and the build's scratch (kept between builds: no allocation once sized).
    std::vector<Node> nodes_;
    std::uint32_t leaf_base_ = 0;
    std::vector<std::uint64_t> codes_, codes_tmp_;
    std::vector<std::uint32_t> order_, order_tmp_;
    std::vector<std::uint32_t> histograms_, all_counts_;
    std::unique_ptr<std::atomic<std::uint32_t>[]> flags_;
    std::size_t flags_size_ = 0;
    std::vector<std::uint32_t> stack_;
};

}  // namespace rcb
