#pragma once
/// Stack-based depth-first traversal of a binary BVH (thesis §4.6, Algorithm 5), shared by the
/// dynamic BVH (dynamic_bvh.h) and the linear BVH (linear_bvh.h): one loop for both, templated on
/// the tree, the counting policy and the visitor (as madmann91/bvh v2 templates its traversal).
///
/// The tree type provides
///     bool is_leaf(std::uint32_t node) const;
///     const Aabb& node_box(std::uint32_t node) const;      // inner nodes
///     std::uint32_t child(std::uint32_t node, int k) const; // inner nodes, k = 0, 1
///     const Aabb& object_box(std::uint32_t node) const;     // leaves: the object's own box
///     const Aabb& leaf_box(std::uint32_t node) const;       // leaves: the box the tree stores
///     Uid leaf_uid(std::uint32_t node) const;
///
/// A leaf is tested against the object's own box (for the DBVH that is not the enlarged "fat" box
/// of the tree, so the hit set stays exact); that test is the N_RB object test. Every node popped
/// from the stack is one traversal step N_T. At the candidate level (counters.h) a leaf is yielded
/// when its stored box is hit, and crowds are not scanned.
///
/// Crowds (optional): a tree that also provides
///     bool has_crowds() const;                  // whether any node is a crowd
///     bool is_crowd(std::uint32_t node) const;
///     template <class Count, class Visit>
///     CrowdScan scan_crowd(std::uint32_t node, const SegmentSlabs&, Count&, Visit&);
/// may answer an inner node whose box the segment meets without descending into it (the LBVH scans
/// its leaves in order when the segment meets every box below: linear_bvh.h).
///
/// Closest hit (hit_policy.h): a visitor with a t_limit takes traverse_bvh_nearest below instead.
///
/// The stack: popping one node and pushing its two children keeps at most height + 1 entries on it
/// (height: edges from the root to the deepest leaf), so the caller passes a buffer of at least
/// height + 2 entries, sized when the tree changes, never per ray; nothing is ever dropped. The
/// closest-hit traversal keeps two words per entry: the buffer holds 2 (height + 2) words.

#include <algorithm>
#include <bit>
#include <concepts>
#include <cstdint>
#include <type_traits>
#include <utility>
#include <vector>

#include "accel/interface/hit_policy.h"
#include "core/base/geometry.h"
#include "core/scene/scene.h"

namespace rcb {

inline constexpr std::uint32_t kNullNode = 0xffffffffu;

/// What a tree's scan_crowd did: nothing (descend as usual), answered the node, or answered it and
/// the visitor asked to stop.
enum class CrowdScan { descend, done, stop };

template <class Tree>
concept HasCrowds = requires(const Tree& t, std::uint32_t n) {
    { t.has_crowds() } -> std::same_as<bool>;
    { t.is_crowd(n) } -> std::same_as<bool>;
};

/// A crowd node (`crowds`: the tree has any) answered by the tree's own scan; `descend` for every
/// other node and at the candidate level, where the walk answers it.
template <class Tree, class Count, class Visit>
CrowdScan scan_if_crowd([[maybe_unused]] const Tree& tree, [[maybe_unused]] bool crowds,
                        [[maybe_unused]] std::uint32_t node, [[maybe_unused]] const SegmentSlabs& slabs,
                        [[maybe_unused]] Count& count, [[maybe_unused]] Visit& visit) {
    if constexpr (HasCrowds<Tree> && !Count::candidates)
        if (crowds && tree.is_crowd(node)) return tree.scan_crowd(node, slabs, count, visit);
    return CrowdScan::descend;
}

/// Closest hits (hit_policy.h), after madmann91/bvh v2's and Embree's single-ray traversals: a
/// node's two children are tested when the node is taken, the segment clipped to the best hit so
/// far (a box entered after t_limit is missed); a leaf child is answered at once, the inner children
/// the segment enters go onto the stack with their entry parameter, the farther first (equal
/// entries by exit). Ordering by entry needs no child centres, which would read both children
/// again; the ray's sign on a split axis is not stored in these trees. An entry
/// popped after the limit dropped below its parameter is skipped without reading the node. A box
/// lies inside its parent's and both entries come from the same float slab computation, monotonic
/// in the bounds, so no object at or before the limit is skipped (ties at the limit are kept).
/// The counters read as traverse_bvh's: every node box tested is a traversal step, every object
/// box test an N_RB test.
template <class Tree, class Count, class Visit>
void traverse_bvh_nearest(const Tree& tree, std::uint32_t root, std::uint32_t* stack, const Segment& s, Count& count,
                          Visit& visit) {
    if (root == kNullNode) return;
    const SegmentSlabs slabs(s);
    bool crowds = false;
    if constexpr (HasCrowds<Tree>) crowds = tree.has_crowds();
    // Tests child (or root) `n` against the segment up to the limit: a leaf is answered (false:
    // the visitor stopped), an inner node entered in time is returned through `t_near`. Meeting
    // the box on [0, 1] with an entry at most the limit is meeting it on [0, min(1, limit)]; the
    // clip keeps its default bounds, so that it inlines here as in traverse_bvh.
    auto take = [&](std::uint32_t n, float& t_near, float& t_far, bool& inner) {
        count.traversal();
        inner = false;
        if (tree.is_leaf(n)) {
            if constexpr (Count::candidates) {
                count.reads(&tree.leaf_box(n), sizeof(Aabb));
                if (!slabs.clip(tree.leaf_box(n), t_near, t_far) || t_near > visit_limit(visit)) return true;
            } else {
                count.box_tests();
                count.reads(&tree.object_box(n), sizeof(Aabb));
                if (!slabs.clip(tree.object_box(n), t_near, t_far) || t_near > visit_limit(visit)) return true;
            }
            count.hits();
            return bool(visit(tree.leaf_uid(n), t_near));
        }
        count.reads(&tree.node_box(n), sizeof(Aabb));
        inner = slabs.clip(tree.node_box(n), t_near, t_far) && t_near <= visit_limit(visit);
        return true;
    };
    float t0, t1, f0, f1;
    bool in0, in1;
    if (!take(root, t0, f0, in0) || !in0) return;
    std::uint32_t top = 0;
    stack[top++] = root;
    stack[top++] = std::bit_cast<std::uint32_t>(t0);
    while (top != 0) {
        top -= 2;
        const std::uint32_t node = stack[top];
        if (std::bit_cast<float>(stack[top + 1]) > visit_limit(visit)) continue;
        const CrowdScan r = scan_if_crowd(tree, crowds, node, slabs, count, visit);
        if (r == CrowdScan::stop) return;
        if (r == CrowdScan::done) continue;
        count.node_hits();
        std::uint32_t c0 = tree.child(node, 0), c1 = tree.child(node, 1);
        if (!take(c0, t0, f0, in0) || !take(c1, t1, f1, in1)) return;
        // Both entered: the farther below, so that the nearer is taken first; equal entries (the
        // segment starts inside both) by exit, the box left first being taken first.
        if (in0 && in1 && (t1 > t0 || (t1 == t0 && f1 > f0))) {
            std::swap(c0, c1);
            std::swap(t0, t1);
        }
        if (in0) {
            stack[top++] = c0;
            stack[top++] = std::bit_cast<std::uint32_t>(t0);
        }
        if (in1) {
            stack[top++] = c1;
            stack[top++] = std::bit_cast<std::uint32_t>(t1);
        }
    }
}

template <class Tree, class Count, class Visit>
void traverse_bvh(const Tree& tree, std::uint32_t root, std::uint32_t* stack, const Segment& s, Count& count,
                  Visit&& visit) {
    if (root == kNullNode) return;
    if constexpr (HasTLimit<std::remove_cvref_t<Visit>>) {
        traverse_bvh_nearest(tree, root, stack, s, count, visit);
        return;
    }
    const SegmentSlabs slabs(s);
    bool crowds = false;  // asked once per ray: a tree without crowds pays nothing per node
    if constexpr (HasCrowds<Tree>) crowds = tree.has_crowds();
    std::uint32_t top = 0;
    stack[top++] = root;
    while (top != 0) {
        const std::uint32_t node = stack[--top];
        count.traversal();
        float t_near, t_far;
        // A block-layout hint, not a measured ratio: without it GCC may lay the inner-node path
        // out of line, as it did once the traversal took a scratch stack (three taken branches
        // per missed inner node instead of one; 2% slower DBVH rays, docs/structures.md). A
        // stronger hint makes the leaf path cold and calls the slab test out of line.
        if (__builtin_expect_with_probability(tree.is_leaf(node), true, 0.25)) {
            if constexpr (Count::candidates) {  // the leaf's stored (for the DBVH, fat) box
                count.reads(&tree.leaf_box(node), sizeof(Aabb));
                if (!slabs.clip(tree.leaf_box(node), t_near, t_far)) continue;
            } else {
                count.box_tests();
                count.reads(&tree.object_box(node), sizeof(Aabb));
                if (!slabs.clip(tree.object_box(node), t_near, t_far)) continue;
            }
            count.hits();
            if (!visit(tree.leaf_uid(node), t_near)) return;
        } else {
            count.reads(&tree.node_box(node), sizeof(Aabb));
            if (!slabs.clip(tree.node_box(node), t_near, t_far)) continue;
            const CrowdScan r = scan_if_crowd(tree, crowds, node, slabs, count, visit);
            if (r == CrowdScan::stop) return;
            if (r == CrowdScan::done) continue;
            // Child 0 on top: visited first.
            count.node_hits();
            stack[top++] = tree.child(node, 1);
            stack[top++] = tree.child(node, 0);
        }
    }
}

/// Sum of half areas (the SAH only needs ratios) over inner nodes and leaves, divided by the root's
/// (thesis eq. 3.2 with C_T = C_I = 1 and one object per leaf). `box_of(node)` gives the node's box
/// in the tree, `visit_children` enumerates. Empty and single-leaf trees cost 1 (or 0 if empty).
template <class BoxOf, class Children>
double sah_cost(std::uint32_t root, BoxOf&& box_of, Children&& children, std::uint32_t node_count) {
    if (root == kNullNode) return 0.0;
    const double root_area = double(box_of(root).half_area());
    std::vector<std::uint32_t> stack{root};
    stack.reserve(64);
    double sum = 0.0;
    std::uint32_t visited = 0;
    while (!stack.empty()) {
        const std::uint32_t n = stack.back();
        stack.pop_back();
        if (++visited > node_count) break;  // a broken tree; check() names it
        sum += double(box_of(n).half_area());
        children(n, stack);
    }
    // A zero-area root (all boxes flat or points): every node has zero area too, so count nodes.
    return root_area > 0 ? sum / root_area : double(visited);
}

}  // namespace rcb
