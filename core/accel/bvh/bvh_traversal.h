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
/// Closest hit (hit_policy.h): a visitor with a t_limit gets the nearer child first (the one whose
/// centre lies earlier along the segment) and a node the segment enters after the limit is
/// skipped. An object's box lies inside its node's box and both entries come from the same float
/// slab computation, which is monotonic in the bound, so no object at or before the limit is ever
/// skipped. Other visitors compile to the loop as before.
///
/// The stack: popping one node and pushing its two children keeps at most height + 1 entries on it
/// (height: edges from the root to the deepest leaf), so the caller passes a buffer of at least
/// height + 2 entries, sized when the tree changes, never per ray; nothing is ever dropped.

#include <concepts>
#include <cstdint>
#include <type_traits>
#include <utility>
#include <vector>

#include "core/accel/hit_policy.h"
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

template <class Tree, class Count, class Visit>
void traverse_bvh(const Tree& tree, std::uint32_t root, std::uint32_t* stack, const Segment& s, Count& count,
                  Visit&& visit) {
    if (root == kNullNode) return;
    constexpr bool kClosest = HasTLimit<std::remove_cvref_t<Visit>>;
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
                if (!slabs.clip(tree.leaf_box(node), t_near, t_far)) continue;
            } else {
                count.box_tests();
                if (!slabs.clip(tree.object_box(node), t_near, t_far)) continue;
            }
            count.hits();
            if (!visit(tree.leaf_uid(node), t_near)) return;
        } else {
            if (!slabs.clip(tree.node_box(node), t_near, t_far)) continue;
            if constexpr (kClosest) {
                if (t_near > visit_limit(visit)) continue;
            }
            if constexpr (HasCrowds<Tree> && !Count::candidates) {
                if (crowds && tree.is_crowd(node)) {
                    const CrowdScan r = tree.scan_crowd(node, slabs, count, visit);
                    if (r == CrowdScan::stop) return;
                    if (r == CrowdScan::done) continue;
                }
            }
            // Child 0 on top: visited first (for closest hits, the nearer child).
            count.node_hits();
            std::uint32_t first = tree.child(node, 0), second = tree.child(node, 1);
            if constexpr (kClosest) {
                auto center = [&](std::uint32_t c) {
                    return (tree.is_leaf(c) ? tree.leaf_box(c) : tree.node_box(c)).center();
                };
                if (dot(center(second) - center(first), s.p1 - s.p0) < 0) std::swap(first, second);
            }
            stack[top++] = second;
            stack[top++] = first;
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
        if (++visited > node_count) break;  // a broken tree; validate() names it
        sum += double(box_of(n).half_area());
        children(n, stack);
    }
    // A zero-area root (all boxes flat or points): every node has zero area too, so count nodes.
    return root_area > 0 ? sum / root_area : double(visited);
}

}  // namespace rcb
