#include "accel/bvh/dynamic_bvh.h"

#include <algorithm>
#include <array>
#include <limits>
#include <stdexcept>
#include <string>

namespace rcb {

namespace {
float area(const Aabb& b) { return b.half_area(); }
}  // namespace

DynamicBvh::DynamicBvh() : DynamicBvh(Params{}) {}

DynamicBvh::DynamicBvh(const Params& p) : params_(p), mode_(parse_choice<Mode>(kModeChoices, p.mode, "dbvh mode")) {
    set_cast_threads(p.cast_threads);
}

std::uint32_t DynamicBvh::allocate() {
    if (free_ != kNullNode) {
        const std::uint32_t n = free_;
        free_ = nodes_[n].child[0];
        --free_count_;
        return n;
    }
    nodes_.push_back({});
    tight_.push_back({});
    return std::uint32_t(nodes_.size() - 1);
}

void DynamicBvh::release(std::uint32_t n) {
    nodes_[n].height = -1;
    nodes_[n].parent = kNullNode;
    nodes_[n].child[0] = free_;
    nodes_[n].child[1] = kNullNode;
    free_ = n;
    ++free_count_;
    ++writes_;
}

Aabb DynamicBvh::fat_box(const Aabb& b) const {
    const float m = float(params_.margin) * b.longest_edge();
    return {b.min - Vec3{m, m, m}, b.max + Vec3{m, m, m}};
}

std::uint32_t DynamicBvh::make_leaf(const Object& o) {
    const std::uint32_t n = allocate();
    nodes_[n] = Node{fat_box(o.box), kNullNode, {o.uid, kNullNode}, 0};
    tight_[n] = o.box;
    ++writes_;
    leaf_of_[o.uid] = n;
    return n;
}

void DynamicBvh::build(std::span<const Object> objects) {
    nodes_.clear();
    tight_.clear();
    leaf_of_.clear();
    root_ = free_ = kNullNode;
    free_count_ = 0;
    dirty_ = false;
    height_rebuilds_ = 0;
    nodes_.reserve(2 * objects.size());
    tight_.reserve(2 * objects.size());
    leaf_of_.reserve(objects.size());
    if (mode_ == Mode::rebuild) {
        for (const Object& o : objects) make_leaf(o);
        rebuild();
    } else {
        // Incremental construction (thesis §4.4): the objects are inserted one by one, unless the
        // tree outgrows the height guard's limit; then the rest only become leaves and one binned
        // build makes the tree.
        std::size_t i = 0;
        for (; i < objects.size(); ++i) {
            insert_leaf(make_leaf(objects[i]));
            if (params_.height_guard && nodes_[root_].height > height_limit(i + 1)) break;
        }
        if (i < objects.size()) {
            for (++i; i < objects.size(); ++i) make_leaf(objects[i]);
            rebuild();
            ++height_rebuilds_;
        }
    }
    changes_since_check_ = 0;
    guard_rebuilds_ = 0;
    guard_baseline_ = mode_ == Mode::incremental && params_.sah_guard > 0 && root_ != kNullNode ? sah_cost() : 0.0;
    look_for_crowds();
}

void DynamicBvh::insert(const Object& o) {
    if (mode_ == Mode::rebuild && !dirty_ && params_.rebuild_every > 0 &&
        frames_since_build_ + 1 >= std::uint32_t(params_.rebuild_every))
        dirty_ = true;  // this frame ends in a rebuild: only the leaves change until commit
    const std::uint32_t leaf = make_leaf(o);
    if (!dirty_) insert_leaf(leaf);
    ++changes_since_check_;
    touch();
}

void DynamicBvh::remove(Uid uid) {
    if (mode_ == Mode::rebuild && !dirty_ && params_.rebuild_every > 0 &&
        frames_since_build_ + 1 >= std::uint32_t(params_.rebuild_every))
        dirty_ = true;
    auto it = leaf_of_.find(uid);
    const std::uint32_t leaf = it->second;
    leaf_of_.erase(it);
    if (!dirty_) remove_leaf(leaf);
    release(leaf);
    ++changes_since_check_;
    touch();
}

void DynamicBvh::move(const Object& o) {
    if (mode_ == Mode::rebuild && !dirty_ && params_.rebuild_every > 0 &&
        frames_since_build_ + 1 >= std::uint32_t(params_.rebuild_every))
        dirty_ = true;
    const std::uint32_t leaf = leaf_of_.at(o.uid);
    tight_[leaf] = o.box;
    ++writes_;
    touch();  // the packed copy of the box is stale even when the tree is not
    // Inside the fat box: the tree still encloses the object, nothing else to do (Box2D's enlarged
    // AABB; the traversal tests the object's own box).
    if (nodes_[leaf].box.contains(o.box)) return;
    if (!dirty_) remove_leaf(leaf);
    nodes_[leaf].box = fat_box(o.box);
    ++writes_;
    if (!dirty_) insert_leaf(leaf);
    ++changes_since_check_;
}

void DynamicBvh::check_sah_guard() {
    if (params_.sah_guard <= 0 || root_ == kNullNode) return;
    if (changes_since_check_ < std::max<std::size_t>(64, leaf_of_.size() / 8)) return;
    changes_since_check_ = 0;
    const double cost = sah_cost();
    if (guard_baseline_ <= 0) {  // built empty: the first tree with objects sets the baseline
        guard_baseline_ = cost;
    } else if (cost > params_.sah_guard * guard_baseline_) {
        rebuild();
        guard_baseline_ = sah_cost();
        ++guard_rebuilds_;
    }
}

void DynamicBvh::commit() {
    if (mode_ == Mode::incremental) {
        check_sah_guard();
        if (params_.height_guard && root_ != kNullNode && nodes_[root_].height > height_limit(leaf_of_.size())) {
            rebuild();
            if (params_.sah_guard > 0) guard_baseline_ = sah_cost();
            ++height_rebuilds_;
        }
    } else {
        ++frames_since_build_;
        if (dirty_) {
            rebuild();
        } else if (params_.rebuild_growth > 0 && root_ != kNullNode &&
                   sah_cost() > params_.rebuild_growth * cost_after_build_) {
            rebuild();
        }
    }
    // Crowds: found again after every change while there are some, else looked for every
    // max(64, size / 8) changes (amortised O(1) per change, as the SAH guard).
    if (crowds_dirty_)
        find_crowds();
    else if (params_.crowd_guard && crowds_.empty() &&
             changes_since_crowd_check_ >= std::max<std::size_t>(64, leaf_of_.size() / 8))
        look_for_crowds();
}

bool DynamicBvh::walk_crowds(bool tight, std::vector<std::uint32_t>& found) {
    found.clear();
    crowds_.clear();
    if (!params_.crowd_guard || root_ == kNullNode) return false;
    // Post-order with child 0 first, leaves numbered in that order (every subtree is then a run).
    // A frame holds what its finished children gave: the first leaf, and the common box while the
    // boxes so far share a point. No per-node arrays: a scene without crowds pays one walk, O(height)
    // memory. With `tight` false the leaves' fat boxes stand in for their own boxes (already in the
    // node: no second array to read); they hold them, so no crowd of fat boxes means no crowd.
    struct Frame {
        std::uint32_t node, first;
        Aabb common;
        bool shared, second;  // `second`: child 0 is done, child 1 is under way
    };
    std::vector<Frame> stack{{root_, 0, {}, true, false}};
    std::uint32_t leaves = 0;
    // What the last finished subtree gives its parent.
    std::uint32_t done_first = 0;
    Aabb done_common;
    bool done_shared = false;
    while (!stack.empty()) {
        Frame& f = stack.back();
        const Node& node = nodes_[f.node];
        if (node.height == 0) {
            done_first = leaves++;
            done_common = tight ? tight_[f.node] : node.box;
            done_shared = true;
            stack.pop_back();
        } else if (f.first == kNullNode) {  // child 0 finished
            f.first = done_first;
            f.common = done_common;
            f.shared = done_shared;
            f.second = true;
            stack.push_back({node.child[1], 0, {}, true, false});
        } else if (!f.second) {  // entering the node
            f.first = kNullNode;
            stack.push_back({node.child[0], 0, {}, true, false});
        } else {  // child 1 finished
            done_shared = f.shared && done_shared;
            if (done_shared) {
                done_common = {rcb::max(f.common.min, done_common.min), rcb::min(f.common.max, done_common.max)};
                const Aabb& c = done_common;
                done_shared = c.min.x <= c.max.x && c.min.y <= c.max.y && c.min.z <= c.max.z;
                if (done_shared && leaves - f.first >= kCrowdLeaves) {
                    found.push_back(f.node);
                    if (tight) {
                        crowds_.push_back({c, f.first, leaves - 1});
                        ++writes_;
                    }
                }
            }
            done_first = f.first;
            stack.pop_back();
        }
    }
    return !found.empty();
}

void DynamicBvh::look_for_crowds() {
    std::vector<std::uint32_t> found;
    if (walk_crowds(false, found)) {
        find_crowds();
        return;
    }
    crowds_dirty_ = false;
    changes_since_crowd_check_ = 0;
    std::vector<std::uint32_t>().swap(crowd_of_);
    std::vector<Crowd>().swap(crowds_);
    std::vector<PackedLeaf>().swap(packed_);
}

void DynamicBvh::find_crowds() {
    crowds_dirty_ = false;
    changes_since_crowd_check_ = 0;
    std::vector<std::uint32_t> found;
    walk_crowds(true, found);
    if (found.empty()) {
        std::vector<std::uint32_t>().swap(crowd_of_);
        std::vector<Crowd>().swap(crowds_);
        std::vector<PackedLeaf>().swap(packed_);
        return;
    }
    crowd_of_.assign(nodes_.size(), kNullNode);
    writes_ += crowd_of_.size();
    for (std::uint32_t k = 0; k < found.size(); ++k) crowd_of_[found[k]] = k;
    writes_ += found.size();
    // The leaves in the same order (pre-order with child 0 first visits them as post-order does).
    packed_.clear();
    packed_.reserve(leaf_of_.size());
    std::vector<std::uint32_t> stack{root_};
    while (!stack.empty()) {
        const std::uint32_t n = stack.back();
        stack.pop_back();
        if (nodes_[n].height == 0) {
            packed_.push_back({tight_[n], nodes_[n].child[0]});
            ++writes_;
        } else
            stack.push_back(nodes_[n].child[1]), stack.push_back(nodes_[n].child[0]);
    }
}

// ---- incremental insertion and removal (Box2D v3 dynamic_tree.c) ----

/// Box2D v3 b_FindBestSibling: a descent with branch and bound. The cost of making node X the
/// sibling of the new leaf L is SA(X ∪ L) plus the inherited cost, the growth of every ancestor's
/// area, Σ SA(P ∪ L) − SA(P). Below an inner child C the cost is at least the inherited cost plus
/// SA(C ∪ L) + min(SA(L) − SA(C), 0); the search stops when neither child's lower bound can beat the
/// best cost found, and otherwise descends into the child with the smaller bound.
// The insertion paths are flattened: they call merge() and half_area() a dozen times each, and
// GCC's unit-growth limit otherwise leaves some of those calls out of line as the file grows.
[[gnu::flatten]] std::uint32_t DynamicBvh::find_best_sibling(const Aabb& box_d) const {
    const float area_d = area(box_d);
    std::uint32_t index = root_;
    const Aabb& root_box = nodes_[index].box;
    float area_index = area(root_box);
    float direct_cost = area(merge(root_box, box_d));
    float inherited_cost = 0.0f;
    std::uint32_t best_sibling = index;
    float best_cost = direct_cost;
    while (nodes_[index].height > 0) {
        const std::uint32_t c1 = nodes_[index].child[0], c2 = nodes_[index].child[1];
        const float cost = direct_cost + inherited_cost;
        if (cost < best_cost) {
            best_sibling = index;
            best_cost = cost;
        }
        inherited_cost += direct_cost - area_index;

        const bool leaf1 = nodes_[c1].height == 0, leaf2 = nodes_[c2].height == 0;
        float lower1 = std::numeric_limits<float>::max(), lower2 = lower1;
        const float direct1 = area(merge(nodes_[c1].box, box_d));
        const float direct2 = area(merge(nodes_[c2].box, box_d));
        float area1 = 0.0f, area2 = 0.0f;
        if (leaf1) {
            const float cost1 = direct1 + inherited_cost;
            if (cost1 < best_cost) {
                best_sibling = c1;
                best_cost = cost1;
            }
        } else {
            area1 = area(nodes_[c1].box);
            lower1 = inherited_cost + direct1 + std::min(area_d - area1, 0.0f);
        }
        if (leaf2) {
            const float cost2 = direct2 + inherited_cost;
            if (cost2 < best_cost) {
                best_sibling = c2;
                best_cost = cost2;
            }
        } else {
            area2 = area(nodes_[c2].box);
            lower2 = inherited_cost + direct2 + std::min(area_d - area2, 0.0f);
        }
        if (leaf1 && leaf2) break;
        if (best_cost <= lower1 && best_cost <= lower2) break;
        if (lower1 == lower2 && !leaf1) {
            // No clear choice by the bound (both children contain the new box, common for points
            // and identical boxes): Box2D falls back to the distance of the centres.
            const Vec3 c = box_d.center();
            const Vec3 d1 = nodes_[c1].box.center() - c, d2 = nodes_[c2].box.center() - c;
            lower1 = d1.x * d1.x + d1.y * d1.y + d1.z * d1.z;
            lower2 = d2.x * d2.x + d2.y * d2.y + d2.z * d2.z;
        }
        if (lower1 < lower2 && !leaf1) {
            index = c1;
            area_index = area1;
            direct_cost = direct1;
        } else {
            index = c2;
            area_index = area2;
            direct_cost = direct2;
        }
    }
    return best_sibling;
}

void DynamicBvh::insert_leaf(std::uint32_t leaf) {
    if (root_ == kNullNode) {
        root_ = leaf;
        nodes_[leaf].parent = kNullNode;
        ++writes_;
        return;
    }
    const Aabb leaf_box = nodes_[leaf].box;
    const std::uint32_t sibling = find_best_sibling(leaf_box);
    const std::uint32_t old_parent = nodes_[sibling].parent;
    const std::uint32_t new_parent = allocate();
    nodes_[new_parent] =
        Node{merge(leaf_box, nodes_[sibling].box), old_parent, {sibling, leaf}, nodes_[sibling].height + 1};
    if (old_parent == kNullNode)
        root_ = new_parent;
    else {
        nodes_[old_parent].child[nodes_[old_parent].child[0] == sibling ? 0 : 1] = new_parent;
        ++writes_;
    }
    nodes_[sibling].parent = new_parent;
    nodes_[leaf].parent = new_parent;
    writes_ += 3;  // the new parent, the sibling and the leaf
    refit_from(new_parent);
}

void DynamicBvh::remove_leaf(std::uint32_t leaf) {
    if (leaf == root_) {
        root_ = kNullNode;
        return;
    }
    const std::uint32_t parent = nodes_[leaf].parent;
    const std::uint32_t grand = nodes_[parent].parent;
    const std::uint32_t sibling = nodes_[parent].child[nodes_[parent].child[0] == leaf ? 1 : 0];
    nodes_[sibling].parent = grand;
    if (grand == kNullNode)
        root_ = sibling;
    else {
        nodes_[grand].child[nodes_[grand].child[0] == parent ? 0 : 1] = sibling;
        ++writes_;
    }
    release(parent);
    nodes_[leaf].parent = kNullNode;
    writes_ += 2;  // the sibling and the leaf
    refit_from(grand);
}

void DynamicBvh::refit_from(std::uint32_t n) {
    while (n != kNullNode) {
        Node& node = nodes_[n];
        const Node& a = nodes_[node.child[0]];
        const Node& b = nodes_[node.child[1]];
        node.box = merge(a.box, b.box);
        node.height = 1 + std::max(a.height, b.height);
        ++writes_;
        if (params_.rotate) rotate_nodes(n);
        n = nodes_[n].parent;
    }
}

/// Box2D v3 b_RotateNodes: swap a child of A with a grandchild on the other side when that shrinks
/// the area of the inner node that changes (the total SAH area, eq. 3.2, falls by the same amount).
/// Names as in Box2D: A's children are B and C, B's children D and E, C's children F and G.
[[gnu::flatten]] void DynamicBvh::rotate_nodes(std::uint32_t ia) {
    Node& A = nodes_[ia];
    if (A.height < 2) return;
    const std::uint32_t ib = A.child[0], ic = A.child[1];
    Node& B = nodes_[ib];
    Node& C = nodes_[ic];
    auto h = [&](std::uint32_t n) { return nodes_[n].height; };
    if (B.height == 0) {
        const std::uint32_t f = C.child[0], g = C.child[1];
        const float base = area(C.box);
        const float cost_bf = area(merge(B.box, nodes_[g].box));
        const float cost_bg = area(merge(B.box, nodes_[f].box));
        if (base <= cost_bf && base <= cost_bg) return;
        // The rotation writes four nodes: A, C and the two swapped ones.
        writes_ += 4;
        if (cost_bf < cost_bg) {  // swap B and F
            A.child[0] = f, C.child[0] = ib, B.parent = ic, nodes_[f].parent = ia;
            C.box = merge(B.box, nodes_[g].box), C.height = 1 + std::max(B.height, h(g));
            A.height = 1 + std::max(C.height, h(f));
        } else {  // swap B and G
            A.child[0] = g, C.child[1] = ib, B.parent = ic, nodes_[g].parent = ia;
            C.box = merge(B.box, nodes_[f].box), C.height = 1 + std::max(B.height, h(f));
            A.height = 1 + std::max(C.height, h(g));
        }
    } else if (C.height == 0) {
        const std::uint32_t d = B.child[0], e = B.child[1];
        const float base = area(B.box);
        const float cost_cd = area(merge(C.box, nodes_[e].box));
        const float cost_ce = area(merge(C.box, nodes_[d].box));
        if (base <= cost_cd && base <= cost_ce) return;
        // The rotation writes four nodes: A, B and the two swapped ones.
        writes_ += 4;
        if (cost_cd < cost_ce) {  // swap C and D
            A.child[1] = d, B.child[0] = ic, C.parent = ib, nodes_[d].parent = ia;
            B.box = merge(C.box, nodes_[e].box), B.height = 1 + std::max(C.height, h(e));
            A.height = 1 + std::max(B.height, h(d));
        } else {  // swap C and E
            A.child[1] = e, B.child[1] = ic, C.parent = ib, nodes_[e].parent = ia;
            B.box = merge(C.box, nodes_[d].box), B.height = 1 + std::max(C.height, h(d));
            A.height = 1 + std::max(B.height, h(e));
        }
    } else {
        const std::uint32_t d = B.child[0], e = B.child[1], f = C.child[0], g = C.child[1];
        const float area_b = area(B.box), area_c = area(C.box);
        const float base = area_b + area_c;
        const std::array<float, 4> cost = {area_b + area(merge(B.box, nodes_[g].box)),   // B↔F
                                           area_b + area(merge(B.box, nodes_[f].box)),   // B↔G
                                           area_c + area(merge(C.box, nodes_[e].box)),   // C↔D
                                           area_c + area(merge(C.box, nodes_[d].box))};  // C↔E
        int best = -1;
        float best_cost = base;
        for (int i = 0; i < 4; ++i)
            if (cost[i] < best_cost) best = i, best_cost = cost[i];
        if (best >= 0) writes_ += 4;  // A, B or C, and the two swapped nodes
        switch (best) {
            case 0:
                A.child[0] = f, C.child[0] = ib, B.parent = ic, nodes_[f].parent = ia;
                C.box = merge(B.box, nodes_[g].box), C.height = 1 + std::max(B.height, h(g));
                A.height = 1 + std::max(C.height, h(f));
                break;
            case 1:
                A.child[0] = g, C.child[1] = ib, B.parent = ic, nodes_[g].parent = ia;
                C.box = merge(B.box, nodes_[f].box), C.height = 1 + std::max(B.height, h(f));
                A.height = 1 + std::max(C.height, h(g));
                break;
            case 2:
                A.child[1] = d, B.child[0] = ic, C.parent = ib, nodes_[d].parent = ia;
                B.box = merge(C.box, nodes_[e].box), B.height = 1 + std::max(C.height, h(e));
                A.height = 1 + std::max(B.height, h(d));
                break;
            case 3:
                A.child[1] = e, B.child[1] = ic, C.parent = ib, nodes_[e].parent = ia;
                B.box = merge(C.box, nodes_[d].box), B.height = 1 + std::max(C.height, h(d));
                A.height = 1 + std::max(B.height, h(e));
                break;
            default:
                break;
        }
    }
}

// ---- full top-down binned-SAH build (rebuild mode) ----

void DynamicBvh::rebuild() {
    build_items_.clear();
    build_items_.reserve(leaf_of_.size());
    for (std::uint32_t n = 0; n < nodes_.size(); ++n) {
        if (nodes_[n].height > 0)
            release(n);
        else if (nodes_[n].height == 0)
            build_items_.push_back({nodes_[n].box, nodes_[n].box.center(), n});
    }
    root_ = build_items_.empty() ? kNullNode : build_range(build_items_.data(), std::uint32_t(build_items_.size()));
    if (!crowds_.empty()) crowds_dirty_ = true;  // new node ids
    if (root_ != kNullNode) {
        nodes_[root_].parent = kNullNode;
        ++writes_;
    }
    dirty_ = false;
    frames_since_build_ = 0;
    cost_after_build_ = params_.rebuild_growth > 0 ? sah_cost() : 0.0;
}

/// Builds the subtree over items[0, count): binned SAH over the centroids (binned_sah.h, Wald 2007)
/// in float, all three axes binned in one pass, one leaf per object, std::partition of the whole
/// range; split by size at the median when no border splits (the centroids coincide).
std::uint32_t DynamicBvh::build_range(SahItem* items, std::uint32_t count) {
    if (count == 1) return items[0].id;
    std::uint32_t mid = count / 2;
    if (count > 2) {
        const Aabb cbounds = grow_centroid_bounds(Aabb::empty(), items, items + count);
        // The bins live in the member sah_ (a local array of 3 × 256 bins would be initialised at
        // every node and dominate the build).
        SahSplit split;
        if (sah_.begin(cbounds, params_.bins)) {
            sah_.add(items, items + count);
            split = sah_.choose(count);
        }
        if (split.found()) {
            mid = std::uint32_t(sah_partition(sah_, split, items, items + count) - items);
            if (mid == 0 || mid == count) mid = count / 2;  // cannot happen with the same binning; be safe
        } else {
            split_by_size<float>(items, count);
        }
    }
    const std::uint32_t left = build_range(items, mid);
    const std::uint32_t right = build_range(items + mid, count - mid);
    const std::uint32_t n = allocate();
    nodes_[n] = Node{merge(nodes_[left].box, nodes_[right].box),
                     kNullNode,
                     {left, right},
                     1 + std::max(nodes_[left].height, nodes_[right].height)};
    nodes_[left].parent = n;
    nodes_[right].parent = n;
    writes_ += 3;  // the node and its children
    return n;
}

// ---- measures and invariants ----

double DynamicBvh::sah_cost() const {
    return rcb::sah_cost(
        root_, [&](std::uint32_t n) -> const Aabb& { return nodes_[n].box; },
        [&](std::uint32_t n, std::vector<std::uint32_t>& stack) {
            if (nodes_[n].height > 0) stack.push_back(nodes_[n].child[0]), stack.push_back(nodes_[n].child[1]);
        },
        std::uint32_t(nodes_.size()));
}

std::size_t DynamicBvh::memory_bytes() const {
    return nodes_.capacity() * sizeof(Node) + tight_.capacity() * sizeof(Aabb) + scratch_bytes() +
           build_items_.capacity() * sizeof(SahItem) + sah_.memory_bytes() + leaf_of_.bucket_count() * sizeof(void*) +
           leaf_of_.size() * (sizeof(void*) + 2 * sizeof(std::uint32_t)) +
           crowd_of_.capacity() * sizeof(std::uint32_t) + crowds_.capacity() * sizeof(Crowd) +
           packed_.capacity() * sizeof(PackedLeaf) + sizeof(*this);
}

nlohmann::json DynamicBvh::stats() const {
    return {{"sah_cost", sah_cost()},
            {"depth", height()},
            {"nodes", nodes_.size() - free_count_},
            {"guard_rebuilds", guard_rebuilds_},
            {"height_rebuilds", height_rebuilds_},
            {"crowds", crowds_.size()}};
}

void DynamicBvh::check() const {
    auto fail = [](const std::string& what) { broken_invariant("dbvh", what); };
    if (dirty_) fail("tree not rebuilt after changes (commit missing)");
    const std::uint32_t total = std::uint32_t(nodes_.size());
    // Free list: every entry a free node, no cycles.
    std::uint32_t free_seen = 0;
    for (std::uint32_t n = free_; n != kNullNode; n = nodes_[n].child[0]) {
        if (n >= total) fail("free list points outside the node array");
        if (nodes_[n].height != -1) fail("node " + std::to_string(n) + " on the free list is in use");
        if (++free_seen > total) fail("free list has a cycle");
    }
    if (free_seen != free_count_)
        fail("free list holds " + std::to_string(free_seen) + " nodes, count says " + std::to_string(free_count_));
    std::uint32_t marked_free = 0;
    for (const Node& node : nodes_) marked_free += node.height == -1;
    if (marked_free != free_seen) fail("free nodes not on the free list");
    // The tree: links, bounds, heights, leaves.
    std::uint32_t reached = 0, leaves = 0;
    if (root_ != kNullNode) {
        if (root_ >= total || nodes_[root_].parent != kNullNode) fail("root has a parent or is out of range");
        std::vector<std::uint32_t> stack{root_};
        while (!stack.empty()) {
            const std::uint32_t n = stack.back();
            stack.pop_back();
            if (++reached > total) fail("tree has a cycle");
            const Node& node = nodes_[n];
            if (node.height < 0) fail("free node " + std::to_string(n) + " is in the tree");
            if (node.height == 0) {
                ++leaves;
                auto it = leaf_of_.find(node.child[0]);
                if (it == leaf_of_.end() || it->second != n)
                    fail("leaf " + std::to_string(n) + " (uid " + std::to_string(node.child[0]) +
                         ") not in the uid index");
                if (!node.box.contains(tight_[n]))
                    fail("fat box of uid " + std::to_string(node.child[0]) + " does not enclose its box");
                continue;
            }
            int hmax = -1;
            for (int k = 0; k < 2; ++k) {
                const std::uint32_t c = node.child[k];
                if (c >= total) fail("child out of range");
                if (nodes_[c].parent != n)
                    fail("child " + std::to_string(c) + " does not point back to parent " + std::to_string(n));
                if (!node.box.contains(nodes_[c].box))
                    fail("node " + std::to_string(n) + " does not enclose child " + std::to_string(c));
                hmax = std::max(hmax, nodes_[c].height);
                stack.push_back(c);
            }
            if (node.height != 1 + hmax) fail("node " + std::to_string(n) + " has a wrong height");
        }
    }
    if (leaves != leaf_of_.size())
        fail(std::to_string(leaf_of_.size()) + " live uids but " + std::to_string(leaves) + " leaves in the tree");
    if (reached + free_seen != total)
        fail("nodes neither in the tree nor free: " + std::to_string(total - reached - free_seen));
    // Crowds: as found afresh now (none is also right between two checks, while the tree has none).
    if (!crowds_dirty_ && !crowds_.empty()) {
        DynamicBvh fresh = *this;
        fresh.find_crowds();
        if (fresh.crowds_ != crowds_ || fresh.crowd_of_ != crowd_of_ || fresh.packed_ != packed_)
            fail("crowds or their packed leaves are stale");
    }
    if (!params_.crowd_guard && !crowds_.empty()) fail("crowds with the crowd guard off");
}

}  // namespace rcb
