#include "core/accel/bvh/wide_bvh.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include <unistd.h>

namespace rcb {

namespace {

/// Half the surface area in double (boxes near the coordinate limit overflow float); 0 for the
/// empty box.
double area(const Aabb& b) {
    if (b.is_empty()) return 0.0;
    const double x = double(b.max.x) - double(b.min.x), y = double(b.max.y) - double(b.min.y),
                 z = double(b.max.z) - double(b.min.z);
    return x * y + y * z + z * x;
}

/// The centre without overflow near the coordinate limit.
Vec3 centroid(const Aabb& b) { return b.min * 0.5f + b.max * 0.5f; }

/// A move's share of a change for the rebuild trigger (Params::rebuild_after): how far its
/// farthest face moved, in units of the object's longest edge (before or after, the longer),
/// capped at one. A step much smaller than the object leaves the tree's partition as good as it
/// was (the refit's growth is what rebuild_ratio watches); a move by its own size or more is as
/// stale as a removal and an insertion. In double: boxes near the coordinate limit overflow float.
double move_share(const Aabb& from, const Aabb& to) {
    double shift = 0, size = 0;
    for (int a = 0; a < 3; ++a) {
        shift = std::max({shift, std::abs(double(to.min[a]) - double(from.min[a])),
                          std::abs(double(to.max[a]) - double(from.max[a]))});
        size = std::max({size, double(from.max[a]) - double(from.min[a]), double(to.max[a]) - double(to.min[a])});
    }
    if (shift == 0) return 0.0;
    return shift < size ? shift / size : 1.0;  // a point's (size 0) or a far jump: a whole change
}

}  // namespace

void WideBvh::Block::clear(int k) {
    constexpr float inf = std::numeric_limits<float>::infinity();
    for (int a = 0; a < 3; ++a) bound[a][k] = inf, bound[3 + a][k] = -inf;
    ref[k] = kNone;
}

Aabb WideBvh::Block::bounds() const {
    // All 8 lanes, branch-free: unused lanes hold the empty box, the identity of the union.
    Aabb b;
    for (int a = 0; a < 3; ++a) {
        float lo = bound[a][0], hi = bound[3 + a][0];
        for (int k = 1; k < kLanes; ++k) lo = std::min(lo, bound[a][k]), hi = std::max(hi, bound[3 + a][k]);
        b.min[a] = lo, b.max[a] = hi;
    }
    return b;
}

WideBvh::WideBvh() : WideBvh(Params{}) {}

WideBvh::WideBvh(const Params& p) : params_(p), push_(parse_choice<Push>(kPushChoices, p.push, "wbvh push")) {
    set_cast_threads(p.cast_threads);
}

std::uint32_t WideBvh::allocate() {
    std::uint32_t b;
    if (free_ != kNone) {
        b = free_;
        free_ = blocks_[b].parent;
        --free_count_;
    } else {
        blocks_.emplace_back();
        b = std::uint32_t(blocks_.size() - 1);
    }
    Block& block = blocks_[b];
    for (int k = 0; k < kLanes; ++k) block.clear(k);
    block.parent = kNone;
    block.depth = 0;
    block.lane_in_parent = 0;
    block.count = 0;
    block.leaf = false;
    block.dirty = false;
    ++writes_;
    return b;
}

void WideBvh::release(std::uint32_t b) {
    Block& block = blocks_[b];
    if (block.leaf) --leaves_;
    block.count = 0;
    block.leaf = false;
    block.dirty = false;
    block.parent = free_;
    free_ = b;
    ++free_count_;
    ++writes_;
}

void WideBvh::mark(std::uint32_t b) {
    changed_ = true;
    if (blocks_[b].dirty) return;
    blocks_[b].dirty = true;
    dirty_.push_back(b);
}

void WideBvh::set_lane(std::uint32_t b, int k, const Aabb& box) {
    Block& block = blocks_[b];
    if (!block.leaf) {
        const double w = weight(block.ref[k]), before = area(block.box(k)) * w, after = area(box) * w;
        sah_sum_ += after - before;
        sah_largest_term_ = std::max({sah_largest_term_, before, after});
    }
    block.set(k, box);
    ++writes_;
}

// ---- build ----

void WideBvh::build(std::span<const Object> objects) {
    // A rebuild in progress is dropped: the new contents replace everything.
    rebuild_.reset();
    changes_ = 0;
    weighted_changes_ = age_ = 0;
    where_.clear();
    where_.reserve(objects.size() + objects.size() / 4);  // room for inserts before a rehash
    std::vector<Item>& items = builder_.items();
    items.clear();
    items.reserve(objects.size());
    for (const Object& o : objects) items.push_back({o.box, centroid(o.box), o.uid});
    rebuilds_ = splits_ = reinserts_ = 0;
    builder_.begin(*this);
    builder_.step(*this, std::numeric_limits<std::uint64_t>::max());
    builder_.end(*this);
    rebuild_.estimate(builder_.work(), objects.size());
}

void WideBvh::rebuild() {
    std::vector<Item>& items = builder_.items();
    items.clear();
    items.reserve(where_.size());
    for (const Block& b : blocks_)
        if (b.leaf)
            for (int k = 0; k < b.count; ++k) items.push_back({b.box(k), centroid(b.box(k)), Uid(b.ref[k])});
    builder_.begin(*this);
    builder_.step(*this, std::numeric_limits<std::uint64_t>::max());
    builder_.end(*this);
    ++rebuilds_;
    age_ = 0;
}

void WideBvh::clear_tree() {
    blocks_.clear();
    root_ = free_ = kNone;
    free_count_ = leaves_ = 0;
    dirty_.clear();
    sah_sum_ = sah_largest_term_ = 0.0;
    max_depth_ = 0;
    changed_ = false;
}

void WideBvh::Builder::begin(WideBvh& t) {
    t.clear_tree();
    // About one leaf per leaf_size objects and one inner node per (width − 1) blocks below.
    t.blocks_.reserve(items_.size() / std::size_t(t.params_.leaf_size) * 8 / 6 + 2);
    pending_.clear();
    opening_ = false;
    splitting_ = -1;
    build_work_ = 0;
    if (!items_.empty()) pending_.push_back({Range{0, std::uint32_t(items_.size())}, kNone, 0, 0});
}

void WideBvh::Builder::end(WideBvh& t) {
    t.grow_stack(t.max_depth_);
    t.total_after_build_ = t.total_sah();
    // The scratch is only needed again at the next rebuild: not held in between.
    std::vector<Item>().swap(items_);
    std::vector<Pending>().swap(pending_);
}

std::uint64_t WideBvh::Builder::step(WideBvh& t, std::uint64_t budget) {
    const Params& params = t.params_;
    std::uint64_t work = 0;
    while (work < budget) {
        if (!opening_) {
            if (pending_.empty()) break;
            const Pending p = pending_.back();
            pending_.pop_back();
            if (p.range.n <= std::uint32_t(params.leaf_size)) {
                make_leaf(t, p);
                work += p.range.n;
                continue;
            }
            open_ = p;
            opening_ = true;
            parts_[0] = p.range;
            nparts_ = 1;
            splitting_ = -1;
        }
        if (splitting_ < 0) {
            // Split the part with the largest box (Wald et al. 2008's collapse of a binary SAH tree
            // into wide nodes, done while building) until `width` parts or none can split.
            int pick = -1;
            double pick_area = 0;
            for (int i = 0; i < nparts_ && nparts_ < params.width; ++i) {
                if (parts_[i].n <= std::uint32_t(params.leaf_size)) continue;
                const double a = area(parts_[i].box);
                if (pick < 0 || a > pick_area || (a == pick_area && parts_[i].n > parts_[pick].n))
                    pick = i, pick_area = a;
            }
            if (pick < 0) {
                finish_node(t);
                work += std::uint64_t(nparts_);
                continue;
            }
            splitting_ = pick;
            stage_ = Stage::centroid_bounds;
            cursor_ = parts_[pick].begin;
            cbox_ = Aabb::empty();
        }
        work += split_step(params, budget - work);
    }
    build_work_ += work;
    return work;
}

std::uint64_t WideBvh::Builder::split_step(const Params& p, std::uint64_t budget) {
    // The loops work on locals (the members could alias the items for the compiler).
    const Range r = parts_[std::size_t(splitting_)];
    const std::uint32_t end = r.begin + r.n;
    const int bins = p.bins;
    Item* const items = items_.data();
    Bin* const bin = bin_scratch_.data();
    std::uint32_t i = cursor_;
    const auto stop = std::uint32_t(std::min<std::uint64_t>(end, i + budget));
    const std::uint64_t work = stop - i;
    if (stage_ == Stage::centroid_bounds) {
        Aabb cb = cbox_;
        for (; i < stop; ++i)
            cb.min = rcb::min(cb.min, items[i].centroid), cb.max = rcb::max(cb.max, items[i].centroid);
        cbox_ = cb;
        cursor_ = i;
        if (i < end) return work;
        bin_scratch_.assign(3 * std::size_t(bins), Bin{Aabb::empty(), 0});
        bool any = false;
        for (int a = 0; a < 3; ++a) {
            const double ext = double(cb.max[a]) - double(cb.min[a]);
            scale_[a] = ext > 0 ? double(bins) / ext : 0.0;
            any = any || ext > 0;
        }
        if (!any) {
            split_by_size(splitting_);
            return work + r.n;
        }
        stage_ = Stage::binning;
        cursor_ = r.begin;
        return work;
    }
    const Vec3 lo = cbox_.min;
    if (stage_ == Stage::binning) {
        const double scale[3] = {scale_[0], scale_[1], scale_[2]};
        for (; i < stop; ++i) {
            const Item& it = items[i];
            for (int a = 0; a < 3; ++a) {
                if (scale[a] == 0) continue;
                Bin& x = bin[a * bins + std::min(bins - 1, int((double(it.centroid[a]) - double(lo[a])) * scale[a]))];
                x.box = merge(x.box, it.box);
                ++x.n;
            }
        }
        cursor_ = i;
        if (i < end) return work;
        if (!choose_split(bins, r.n)) {
            split_by_size(splitting_);
            return work + r.n;
        }
        stage_ = Stage::partition;
        cursor_ = r.begin;
        right_ = r.begin + left_n_;
        return work;
    }
    // Partition: the items of the left part's bins to [begin, begin + left_n_), swapped with the
    // right part's items found there; resumable at any item.
    const int axis = axis_, split_bin = split_bin_;
    const double from = double(lo[axis]), scale = scale_[axis];
    auto goes_left = [&](const Item& it) {
        return std::min(bins - 1, int((double(it.centroid[axis]) - from) * scale)) < split_bin;
    };
    const std::uint32_t mid = r.begin + left_n_;
    std::uint32_t j = right_;
    std::uint64_t done = 0;
    for (; done < budget && i < mid; ++done) {
        if (goes_left(items[i])) {
            ++i;
        } else {
            if (goes_left(items[j])) std::swap(items[i], items[j]), ++i;
            ++j;
        }
    }
    cursor_ = i, right_ = j;
    if (i < mid) return done;
    // The parts' boxes are the unions of their bins'.
    Aabb left = Aabb::empty(), right = Aabb::empty();
    for (int k = 0; k < bins; ++k)
        (k < split_bin ? left : right) = merge(k < split_bin ? left : right, bin[axis * bins + k].box);
    parts_[std::size_t(nparts_++)] = Range{mid, r.n - left_n_, right};
    parts_[std::size_t(splitting_)] = Range{r.begin, left_n_, left};
    splitting_ = -1;
    return done;
}

bool WideBvh::Builder::choose_split(int bins, std::uint32_t n) {
    // Binned SAH (Wald 2007): cost area(left)·n_left + area(right)·n_right per bin border.
    auto bin = [&](int axis) { return bin_scratch_.data() + std::size_t(axis) * std::size_t(bins); };
    int best_axis = -1, best_split = 0;
    double best_cost = std::numeric_limits<double>::infinity();
    std::vector<double>& right = right_cost_;
    right.resize(std::size_t(bins));
    for (int a = 0; a < 3; ++a) {
        if (scale_[a] == 0) continue;
        Aabb acc = Aabb::empty();
        std::uint32_t m = 0;
        for (int k = bins - 1; k > 0; --k) {
            acc = merge(acc, bin(a)[k].box), m += bin(a)[k].n;
            right[std::size_t(k)] = area(acc) * double(m);
        }
        acc = Aabb::empty(), m = 0;
        for (int k = 0; k < bins - 1; ++k) {
            acc = merge(acc, bin(a)[k].box), m += bin(a)[k].n;
            if (m == 0 || m == n) continue;
            const double cost = area(acc) * double(m) + right[std::size_t(k) + 1];
            if (cost < best_cost) best_cost = cost, best_axis = a, best_split = k + 1;
        }
    }
    if (best_axis < 0) return false;
    axis_ = best_axis;
    split_bin_ = best_split;
    left_n_ = 0;
    for (int k = 0; k < best_split; ++k) left_n_ += bin(best_axis)[k].n;
    return left_n_ > 0 && left_n_ < n;
}

void WideBvh::Builder::split_by_size(int part) {
    const Range r = parts_[std::size_t(part)];
    Item* items = items_.data() + r.begin;
    const std::uint32_t half = r.n / 2;
    if (scale_[0] == 0 && scale_[1] == 0 && scale_[2] == 0) {
        // One centroid (boxes nested around one centre, or duplicates): split by size, smallest
        // half first, ties by uid, so that a subtree holds boxes of similar size.
        std::nth_element(items, items + half, items + r.n, [](const Item& x, const Item& y) {
            const double ax = area(x.box), ay = area(y.box);
            return ax < ay || (ax == ay && x.uid < y.uid);
        });
    } else {
        // Binning could not split: the median on the widest axis of the centroids.
        int axis = 0;
        for (int a = 1; a < 3; ++a)
            if (double(cbox_.max[a]) - double(cbox_.min[a]) > double(cbox_.max[axis]) - double(cbox_.min[axis]))
                axis = a;
        std::nth_element(items, items + half, items + r.n, [axis](const Item& x, const Item& y) {
            return x.centroid[axis] < y.centroid[axis] || (x.centroid[axis] == y.centroid[axis] && x.uid < y.uid);
        });
    }
    Aabb left = Aabb::empty(), right = Aabb::empty();
    for (std::uint32_t i = 0; i < r.n; ++i) (i < half ? left : right) = merge(i < half ? left : right, items[i].box);
    parts_[std::size_t(nparts_++)] = Range{r.begin + half, r.n - half, right};
    parts_[std::size_t(part)] = Range{r.begin, half, left};
    splitting_ = -1;
}

void WideBvh::Builder::finish_node(WideBvh& t) {
    const std::uint32_t b = t.allocate();
    Block& block = t.blocks_[b];
    block.depth = open_.depth;
    block.count = std::uint8_t(nparts_);
    for (int j = 0; j < nparts_; ++j) block.set(j, parts_[std::size_t(j)].box);
    t.max_depth_ = std::max(t.max_depth_, int(open_.depth));
    t.link(b, open_.parent, open_.lane);
    // Children in reverse, so that the first part is built next (depth first, in lane order).
    for (int j = nparts_ - 1; j >= 0; --j)
        pending_.push_back({parts_[std::size_t(j)], b, std::uint16_t(open_.depth + 1), std::uint8_t(j)});
    opening_ = false;
}

void WideBvh::Builder::make_leaf(WideBvh& t, const Pending& p) {
    const std::uint32_t b = t.allocate();
    Block& block = t.blocks_[b];
    block.leaf = true;
    block.depth = p.depth;
    block.count = std::uint8_t(p.range.n);
    ++t.leaves_;
    for (std::uint32_t i = 0; i < p.range.n; ++i) {
        const Item& it = items_[p.range.begin + i];
        block.set(int(i), it.box);
        block.ref[i] = it.uid;
        t.where_[it.uid] = b * kLanes + i;
    }
    t.max_depth_ = std::max(t.max_depth_, int(p.depth));
    t.link(b, p.parent, p.lane);
}

void WideBvh::link(std::uint32_t b, std::uint32_t parent, int lane) {
    blocks_[b].parent = parent;
    blocks_[b].lane_in_parent = std::uint8_t(lane);
    if (parent == kNone) {
        root_ = b;
        return;
    }
    blocks_[parent].ref[lane] = b;
    const double term = area(blocks_[parent].box(lane)) * weight(b);
    sah_sum_ += term;
    sah_largest_term_ = std::max(sah_largest_term_, term);
}

std::uint32_t WideBvh::Builder::split(const Params& p, Item* items, std::uint32_t n) {
    // The build's split run whole on these items: no build is in progress in this tree when one of
    // its leaves splits (builds run to their end, or in the next tree of a progressive rebuild).
    items_.assign(items, items + n);
    parts_[0] = Range{0, n};
    nparts_ = 1;
    splitting_ = 0;
    stage_ = Stage::centroid_bounds;
    cursor_ = 0;
    cbox_ = Aabb::empty();
    while (splitting_ >= 0) split_step(p, std::numeric_limits<std::uint64_t>::max());
    std::copy(items_.begin(), items_.end(), items);
    items_.clear();
    return parts_[0].n;
}

// ---- changes ----

std::uint32_t WideBvh::choose_leaf(const Aabb& box) const {
    std::uint32_t b = root_;
    while (!blocks_[b].leaf) {
        const Block& block = blocks_[b];
        int best = 0;
        double best_growth = std::numeric_limits<double>::infinity(), best_area = best_growth;
        for (int k = 0; k < block.count; ++k) {
            const Aabb lane = block.box(k);
            const double a = area(lane), growth = area(merge(lane, box)) - a;
            if (growth < best_growth || (growth == best_growth && a < best_area))
                best = k, best_growth = growth, best_area = a;
        }
        b = block.ref[best];
    }
    return b;
}

void WideBvh::insert(const Object& o) {
    ++changes_;
    weighted_changes_ += 1;
    rebuild_.log_change(o.uid);
    insert_object(o);
}

void WideBvh::insert_object(const Object& o) {
    changed_ = true;
    if (root_ == kNone) {
        root_ = allocate();
        Block& block = blocks_[root_];
        block.leaf = true;
        block.count = 1;
        block.set(0, o.box);
        block.ref[0] = o.uid;
        ++leaves_;
        where_[o.uid] = root_ * kLanes;
        grow_stack(0);
        return;
    }
    const std::uint32_t leaf = choose_leaf(o.box);
    Block& block = blocks_[leaf];
    if (block.count == kLanes) {
        split_leaf(leaf, o);
        return;
    }
    const int k = block.count++;
    block.set(k, o.box);
    block.ref[k] = o.uid;
    ++writes_;
    where_[o.uid] = leaf * kLanes + std::uint32_t(k);
    if (leaf != root_) {  // its weight grew by one
        const double a = area(blocks_[block.parent].box(block.lane_in_parent));
        sah_sum_ += a;
        sah_largest_term_ = std::max(sah_largest_term_, a);
    }
    mark(leaf);
}

void WideBvh::split_leaf(std::uint32_t leaf, const Object& o) {
    ++splits_;
    std::array<Item, kLanes + 1> nine;
    {
        const Block& block = blocks_[leaf];
        for (int k = 0; k < kLanes; ++k) {
            nine[std::size_t(k)] = {block.box(k), centroid(block.box(k)), Uid(block.ref[k])};
            rebuild_.log_relocation(Uid(block.ref[k]));
        }
    }
    nine[kLanes] = {o.box, centroid(o.box), o.uid};
    where_[o.uid] = 0;
    const std::uint32_t m = builder_.split(params_, nine.data(), kLanes + 1);
    // Take the leaf's term out of the running sum; set_lane below adds the new ones.
    const std::uint32_t parent = blocks_[leaf].parent;
    const int lane = blocks_[leaf].lane_in_parent;
    if (parent != kNone) {
        const double a = area(blocks_[parent].box(lane)) * weight(leaf);
        sah_sum_ -= a;
        sah_largest_term_ = std::max(sah_largest_term_, a);
        blocks_[parent].clear(lane);
        blocks_[parent].ref[lane] = leaf;
        ++writes_;
    }
    const std::uint32_t other = allocate();
    auto fill = [&](std::uint32_t b, const Item* items, std::uint32_t count) {
        Block& block = blocks_[b];
        for (int k = 0; k < kLanes; ++k) block.clear(k);
        block.leaf = true;
        block.count = std::uint8_t(count);
        for (std::uint32_t i = 0; i < count; ++i) {
            block.set(int(i), items[i].box);
            block.ref[i] = items[i].uid;
            where_.find(items[i].uid)->second = b * kLanes + i;
        }
        ++writes_;  // the block, whole
    };
    fill(leaf, nine.data(), m);
    fill(other, nine.data() + m, kLanes + 1 - m);
    ++leaves_;
    if (parent != kNone && blocks_[parent].count < kLanes) {
        // Side by side in the parent.
        Block& p = blocks_[parent];
        const int k = p.count++;
        p.ref[k] = other;
        blocks_[other].parent = parent;
        blocks_[other].lane_in_parent = std::uint8_t(k);
        blocks_[other].depth = blocks_[leaf].depth;
        set_lane(parent, lane, blocks_[leaf].bounds());
        set_lane(parent, k, blocks_[other].bounds());
        mark(parent);
        return;
    }
    // Below a new inner node in the leaf's place (the parent is full, or the leaf is the root).
    const std::uint32_t inner = allocate();
    Block& in = blocks_[inner];
    in.parent = parent;
    in.lane_in_parent = std::uint8_t(lane);
    in.depth = blocks_[leaf].depth;
    in.count = 2;
    in.ref[0] = leaf;
    in.ref[1] = other;
    for (int k = 0; k < 2; ++k) {
        Block& c = blocks_[in.ref[k]];
        c.parent = inner;
        c.lane_in_parent = std::uint8_t(k);
        c.depth = std::uint16_t(in.depth + 1);
    }
    grow_stack(in.depth + 1);
    set_lane(inner, 0, blocks_[leaf].bounds());
    set_lane(inner, 1, blocks_[other].bounds());
    if (parent == kNone) {
        root_ = inner;
    } else {
        blocks_[parent].ref[lane] = inner;
        set_lane(parent, lane, blocks_[inner].bounds());
        mark(parent);
    }
}

void WideBvh::remove(Uid uid) {
    ++changes_;
    weighted_changes_ += 1;
    rebuild_.log_change(uid);
    remove_object(uid);
}

void WideBvh::remove_object(Uid uid) {
    auto it = where_.find(uid);
    const std::uint32_t b = it->second / kLanes;
    const int k = int(it->second % kLanes);
    where_.erase(it);
    Block& block = blocks_[b];
    const int last = block.count - 1;
    if (k != last) {
        block.set(k, block.box(last));
        block.ref[k] = block.ref[last];
        ++writes_;
        where_.find(Uid(block.ref[k]))->second = b * kLanes + std::uint32_t(k);
        rebuild_.log_relocation(Uid(block.ref[k]));
    }
    block.clear(last);
    ++writes_;
    --block.count;
    changed_ = true;
    if (b != root_) {  // its weight fell by one
        const double a = area(blocks_[block.parent].box(block.lane_in_parent));
        sah_sum_ -= a;
        sah_largest_term_ = std::max(sah_largest_term_, a);
    }
    if (block.count == 0)
        remove_block(b);
    else
        mark(b);
}

void WideBvh::remove_block(std::uint32_t b) {
    if (b == root_) {
        release(b);
        root_ = kNone;
        return;
    }
    const std::uint32_t parent = blocks_[b].parent;
    const int lane = blocks_[b].lane_in_parent;
    const double a = area(blocks_[parent].box(lane)) * weight(b);
    sah_sum_ -= a;
    sah_largest_term_ = std::max(sah_largest_term_, a);
    release(b);
    drop_child_lane(parent, lane);
    if (blocks_[parent].count == 0)
        remove_block(parent);
    else
        mark(parent);
}

void WideBvh::drop_child_lane(std::uint32_t b, int k) {
    Block& block = blocks_[b];
    const int last = block.count - 1;
    if (k != last) {
        block.set(k, block.box(last));
        block.ref[k] = block.ref[last];
        blocks_[block.ref[k]].lane_in_parent = std::uint8_t(k);
        ++writes_;
    }
    block.clear(last);
    ++writes_;
    --block.count;
}

void WideBvh::move(const Object& o) {
    ++changes_;
    rebuild_.log_change(o.uid);
    const std::uint32_t at = where_.at(o.uid);
    const std::uint32_t b = at / kLanes;
    if (params_.reinsert && b != root_) {
        const Block& leaf = blocks_[b];
        const Aabb box = blocks_[leaf.parent].box(leaf.lane_in_parent);
        const Vec3 c = centroid(o.box);
        if (!(box.min.x <= c.x && c.x <= box.max.x && box.min.y <= c.y && c.y <= box.max.y && box.min.z <= c.z &&
              c.z <= box.max.z)) {
            ++reinserts_;
            weighted_changes_ += 1;  // a removal and an insertion
            remove_object(o.uid);
            insert_object(o);
            return;
        }
    }
    const int k = int(at % kLanes);
    weighted_changes_ += move_share(blocks_[b].box(k), o.box);
    blocks_[b].set(k, o.box);
    ++writes_;
    mark(b);
}

/// Bottom-up refit of the marked blocks in one pass, the deepest level first: a block's box is
/// computed once and written into its lane in the parent, and the parent joins the level above
/// only when that lane changed (above an unchanged lane the boxes already enclose what changed).
/// So a block is refitted at most once per commit however many of its children changed, where a
/// walk up from every marked block recomputed a shared ancestor once per changed child. While the
/// pass runs, a block's `dirty` flag means "queued, not refitted yet".
void WideBvh::refit() {
    if (dirty_.empty()) return;
    // Every block's depth is at most max_depth_ and a child's is its parent's plus one
    // (validate_tree checks both), so the parent of a block at `level` belongs to level − 1.
    if (refit_levels_.size() < std::size_t(max_depth_) + 1) refit_levels_.resize(std::size_t(max_depth_) + 1);
    for (const std::uint32_t d : dirty_)
        if (blocks_[d].dirty) refit_levels_[blocks_[d].depth].push_back(d);  // a released block is unmarked
    dirty_.clear();
    for (std::size_t level = refit_levels_.size(); level-- > 0;) {
        std::vector<std::uint32_t>& queue = refit_levels_[level];
        for (const std::uint32_t c : queue) {
            Block& block = blocks_[c];
            // Listed twice when released and reused after it was first marked: refitted once.
            if (!block.dirty) continue;
            block.dirty = false;
            if (c == root_) continue;
            const Aabb box = block.bounds();
            ++refit_blocks_;
            ++writes_;
            const std::uint32_t p = block.parent;
            if (box == blocks_[p].box(block.lane_in_parent)) continue;
            set_lane(p, block.lane_in_parent, box);
            ++refit_lanes_;
            if (!blocks_[p].dirty) {
                blocks_[p].dirty = true;
                refit_levels_[level - 1].push_back(p);
            }
        }
        queue.clear();
    }
}

void WideBvh::commit() {
    refit_blocks_ = refit_lanes_ = 0;
    refit();
    rebuild_.open_commit();
    if (!changed_) return;
    changed_ = false;
    if (sah_largest_term_ > 1e6 * std::abs(sah_sum_)) {
        sah_sum_ = fresh_sah_sum();
        sah_largest_term_ = std::abs(sah_sum_);
    }
    const std::uint64_t changes = changes_;
    const double weighted = weighted_changes_;
    changes_ = 0;
    weighted_changes_ = 0;
    age_ += weighted;
    rebuild_.commit(*this, changes, weighted);
}

// ---- progressive rebuild ----
//
// PhysX's dynamic pruner keeps one tree for queries while the next one is built over many frames,
// new objects in a side structure meanwhile; Jolt's quad tree builds the next tree while the old
// one answers, then swaps. Here the live tree takes every change as before (so no side structure
// is needed), and the next tree is built from a gathering of the live objects, a budget of work
// per commit; the uids changed since the gathering began are logged and replayed into the next
// tree (present or not, same box as in the live tree), then the trees swap and the replaced one is
// freed, again within the budget. Answers come from the live tree throughout, so they stay exact.

bool WideBvh::rebuild_due() const {
    if (root_ == kNone) return false;
    const double ratio = params_.rebuild_ratio;
    if (ratio > 0 && (ratio <= 1 || sah_growth() > ratio)) return true;
    return params_.rebuild_after > 0 && age_ >= params_.rebuild_after * double(where_.size());
}

void WideBvh::ProgressiveRebuild::reset() {
    phase_ = Phase::idle;
    next_.reset();
    log_.clear();
    log_mark_ = 0;
    gather_skip_.clear();
    replay_cursor_ = 0;
    cycle_age_ = 0;
    cycle_work_ = last_cycle_work_ = budget_ = work_ = 0;
}

void WideBvh::ProgressiveRebuild::estimate(std::uint64_t build_work, std::size_t objects) {
    units_per_object_ = double(build_work) / double(std::max<std::size_t>(1, objects)) + 2;
}

void WideBvh::ProgressiveRebuild::commit(WideBvh& live, std::uint64_t changes, double weighted) {
    cycle_age_ += weighted;
    const Params& params = live.params_;
    if (phase_ == Phase::idle && live.rebuild_due()) {
        if (params.rebuild_speed <= 0) {
            live.rebuild();
            return;
        }
        start(live);
    }
    if (phase_ == Phase::idle) return;
    budget_ = std::uint64_t(std::ceil(params.rebuild_speed * double(changes) * units_per_object_));
    // While replaying, the uids logged since the last commit are replayed on top of the budget: the
    // log then shrinks by the budget's share at every commit, however slow the rebuild.
    if (phase_ == Phase::replay) budget_ += (log_.size() - log_mark_) * kReplayUnits;
    advance(live, budget_);
    log_mark_ = log_.size();
}

void WideBvh::ProgressiveRebuild::start(const WideBvh& live) {
    if (!next_) {
        Params p = live.params_;
        p.rebuild_ratio = p.rebuild_after = p.rebuild_speed = 0;
        p.cast_threads = 1;
        next_ = std::make_unique<WideBvh>(p);
    }
    const std::size_t n = live.where_.size();
    next_->builder_.items().clear();
    next_->builder_.items().reserve(n);
    next_->where_.reserve(n + n / 4);  // room for inserts before a rehash
    phase_ = Phase::gather;
    gather_cursor_ = 0;
    log_.clear();
    log_mark_ = 0;
    gather_skip_.clear();
    replay_cursor_ = 0;
    cycle_age_ = 0;
    cycle_work_ = 0;
}

void WideBvh::ProgressiveRebuild::advance(WideBvh& live, std::uint64_t budget) {
    // The next tree counts the blocks its build, replay and refit write; the live tree reports them.
    const std::uint64_t next_writes = next_->writes_;
    while (work_ < budget && phase_ != Phase::idle) {
        std::uint64_t w = 0;
        switch (phase_) {
            case Phase::gather:
                w = gather_step(live, budget - work_);
                break;
            case Phase::build:
                w = next_->builder_.step(*next_, budget - work_);
                if (next_->builder_.done()) {
                    next_->builder_.end(*next_);
                    phase_ = Phase::replay;
                }
                break;
            case Phase::replay:
                while (work_ + w < budget && replay_cursor_ < log_.size()) {
                    replay(live, log_[replay_cursor_++]);
                    w += kReplayUnits;
                }
                if (replay_cursor_ == log_.size()) {
                    work_ += w, cycle_work_ += w, w = 0;
                    swap_trees(live);
                }
                break;
            case Phase::dispose: {
                auto& index = next_->where_;
                while (work_ + w < budget && !index.empty()) {
                    index.erase(index.begin());
                    w += kDisposeUnits;
                }
                if (index.empty()) {  // the rest is a few arrays, freed at once
                    next_->clear_tree();
                    std::vector<Block>().swap(next_->blocks_);
                    std::vector<std::uint32_t>().swap(next_->dirty_);
                    std::unordered_map<Uid, std::uint32_t>().swap(index);
                    phase_ = Phase::idle;
                }
                break;
            }
            case Phase::idle:
                break;
        }
        work_ += w;
        cycle_work_ += w;
    }
    live.writes_ += next_->writes_ - next_writes;
}

std::uint64_t WideBvh::ProgressiveRebuild::gather_step(const WideBvh& live, std::uint64_t budget) {
    std::uint64_t w = 0;
    std::vector<Item>& items = next_->builder_.items();
    const std::vector<Block>& blocks = live.blocks_;
    while (w < budget && gather_cursor_ < blocks.size()) {
        const Block& b = blocks[gather_cursor_++];
        ++w;
        if (!b.leaf) continue;
        for (int k = 0; k < b.count; ++k) {
            // An object changed since the gathering began is left to the replay: it may have been
            // gathered already, or not at all (its lane moved).
            const Uid uid = b.ref[k];
            if (gather_skip_.empty() || gather_skip_.count(uid) == 0)
                items.push_back({b.box(k), centroid(b.box(k)), uid});
        }
        w += b.count;
    }
    if (gather_cursor_ == blocks.size()) {
        gather_skip_.clear();
        next_->builder_.begin(*next_);
        phase_ = Phase::build;
    }
    return w;
}

void WideBvh::ProgressiveRebuild::replay(const WideBvh& live, Uid uid) {
    WideBvh& next = *next_;
    const auto in_live = live.where_.find(uid);
    const auto in_next = next.where_.find(uid);
    if (in_live == live.where_.end()) {
        if (in_next != next.where_.end()) next.remove(uid);
        return;
    }
    const Aabb box = live.blocks_[in_live->second / kLanes].box(int(in_live->second % kLanes));
    if (in_next == next.where_.end())
        next.insert(Object(uid, box));
    else if (!(next.blocks_[in_next->second / kLanes].box(int(in_next->second % kLanes)) == box))
        next.move(Object(uid, box));
}

void WideBvh::ProgressiveRebuild::swap_trees(WideBvh& live) {
    WideBvh& next = *next_;
    next.commit();  // refits what the replay changed
    std::swap(live.blocks_, next.blocks_);
    std::swap(live.root_, next.root_);
    std::swap(live.free_, next.free_);
    std::swap(live.free_count_, next.free_count_);
    std::swap(live.leaves_, next.leaves_);
    std::swap(live.where_, next.where_);
    std::swap(live.dirty_, next.dirty_);
    std::swap(live.max_depth_, next.max_depth_);
    std::swap(live.sah_sum_, next.sah_sum_);
    std::swap(live.sah_largest_term_, next.sah_largest_term_);
    live.total_after_build_ = live.total_sah();
    live.age_ = cycle_age_;
    last_cycle_work_ = cycle_work_;
    units_per_object_ = double(cycle_work_) / double(std::max<std::size_t>(1, live.where_.size()));
    ++live.rebuilds_;
    log_.clear();
    log_mark_ = 0;
    replay_cursor_ = 0;
    phase_ = Phase::dispose;
}

// ---- measures and invariants ----

double WideBvh::fresh_sah_sum() const {
    double sum = 0.0;
    for (std::uint32_t b = 0; b < blocks_.size(); ++b) {
        const Block& block = blocks_[b];
        if (block.count == 0 || b == root_) continue;
        sum += area(blocks_[block.parent].box(block.lane_in_parent)) * weight(b);
    }
    return sum;
}

double WideBvh::total_sah() const {
    return root_ == kNone ? 0.0 : area(blocks_[root_].bounds()) * weight(root_) + sah_sum_;
}

double WideBvh::sah_growth() const {
    const double now = total_sah();
    if (total_after_build_ > 0) return now / total_after_build_;
    return now > 0 ? std::numeric_limits<double>::infinity() : 1.0;
}

double WideBvh::sah_cost() const {
    if (root_ == kNone) return 0.0;
    const double root_area = area(blocks_[root_].bounds());
    // A zero-area root (points or segments only): every box is met by a ray that meets the root,
    // so count the blocks and the objects.
    if (!(root_area > 0)) return double(blocks_.size() - free_count_) + double(where_.size());
    return (root_area * weight(root_) + sah_sum_) / root_area;
}

int WideBvh::depth() const {
    if (root_ == kNone) return -1;
    int deepest = 0;
    for (const Block& b : blocks_)
        if (b.leaf && b.count > 0) deepest = std::max(deepest, int(b.depth));
    return deepest;
}

std::size_t WideBvh::l2_bytes() {
    static const std::size_t bytes = [] {
        const long b = sysconf(_SC_LEVEL2_CACHE_SIZE);
        return b > 0 ? std::size_t(b) : std::size_t(1) << 20;
    }();
    return bytes;
}

std::size_t WideBvh::Builder::memory_bytes() const {
    return items_.capacity() * sizeof(Item) + pending_.capacity() * sizeof(Pending) +
           bin_scratch_.capacity() * sizeof(Bin) + right_cost_.capacity() * sizeof(double);
}

std::size_t WideBvh::ProgressiveRebuild::memory_bytes() const {
    std::size_t bytes = log_.capacity() * sizeof(Uid) + gather_skip_.bucket_count() * sizeof(void*) +
                        gather_skip_.size() * 2 * sizeof(void*);
    if (next_) bytes += next_->memory_bytes();
    return bytes;
}

std::size_t WideBvh::memory_bytes() const {
    return blocks_.capacity() * sizeof(Block) + where_.bucket_count() * sizeof(void*) +
           where_.size() * (sizeof(void*) + 2 * sizeof(std::uint32_t)) + dirty_.capacity() * sizeof(std::uint32_t) +
           refit_levels_bytes() + scratch_bytes() + builder_.memory_bytes() + rebuild_.memory_bytes() + sizeof(*this);
}

void WideBvh::ProgressiveRebuild::add_stats(nlohmann::json& stats) const {
    static constexpr const char* kPhases[] = {"idle", "gather", "build", "replay", "dispose"};
    stats["rebuild_phase"] = kPhases[int(phase_)];
    stats["rebuild_budget"] = budget_;
    stats["rebuild_work"] = work_;
    stats["rebuilt_objects"] = units_per_object_ > 0 ? double(work_) / units_per_object_ : 0.0;
    stats["last_rebuild_work"] = last_cycle_work_;
}

nlohmann::json WideBvh::stats() const {
    nlohmann::json stats = {{"sah_cost", sah_cost()}, {"sah_growth", sah_growth()},
                            {"depth", depth()},       {"nodes", blocks_.size() - free_count_},
                            {"leaves", leaves_},      {"rebuilds", rebuilds_},
                            {"leaf_splits", splits_}, {"reinserts", reinserts_}};
    // The weighted changes since the live tree's objects were gathered, per object: a rebuild
    // starts at commit once this reaches rebuild_after.
    stats["rebuild_age"] = where_.empty() ? 0.0 : age_ / double(where_.size());
    // The last commit's refit: blocks whose box it computed (each at most once), and the lanes of
    // their parents it rewrote (with any refit a query's prepare ran after it).
    stats["refit_blocks"] = refit_blocks_;
    stats["refit_lanes"] = refit_lanes_;
    rebuild_.add_stats(stats);
    return stats;
}

void WideBvh::validate() const {
    validate_tree(true);
    rebuild_.validate(*this);
}

void WideBvh::ProgressiveRebuild::validate(const WideBvh& live) const {
    auto fail = [](const std::string& what) { broken_invariant("wbvh", what); };
    if (phase_ == Phase::idle) {
        if (!log_.empty() || replay_cursor_ != 0 || !gather_skip_.empty()) fail("a change log without a rebuild");
        if (next_ && (next_->root_ != kNone || !next_->where_.empty() || !next_->blocks_.empty()))
            fail("the replaced tree is not freed");
        return;
    }
    if (!next_) fail("a rebuild without a next tree");
    if (replay_cursor_ > log_.size()) fail("the replay is past the end of the log");
    if (phase_ != Phase::gather && !gather_skip_.empty()) fail("uids left to skip after the gathering");
    if (phase_ == Phase::dispose) return;
    // The swap's precondition, kept from the gathering on: the next tree (its items while they are
    // gathered and built) holds every live uid with its live box, except uids still to replay.
    const std::unordered_set<Uid> to_replay(log_.begin() + std::ptrdiff_t(replay_cursor_), log_.end());
    auto live_box = [&](Uid uid, const Aabb& box) {
        const auto it = live.where_.find(uid);
        return it != live.where_.end() && live.blocks_[it->second / kLanes].box(int(it->second % kLanes)) == box;
    };
    if (phase_ == Phase::replay) {
        next_->validate_tree(false);
        for (const auto& [uid, at] : next_->where_)
            if (to_replay.count(uid) == 0 && !live_box(uid, next_->blocks_[at / kLanes].box(int(at % kLanes))))
                fail("uid " + std::to_string(uid) + " of the next tree is not live with that box, and not logged");
        for (const auto& [uid, at] : live.where_)
            if (to_replay.count(uid) == 0 && next_->where_.count(uid) == 0)
                fail("live uid " + std::to_string(uid) + " is not in the next tree, and not logged");
        return;
    }
    std::unordered_set<Uid> gathered;
    for (const Item& it : next_->builder_.items()) {
        if (!gathered.insert(it.uid).second) fail("uid " + std::to_string(it.uid) + " gathered twice");
        if (to_replay.count(it.uid) == 0 && !live_box(it.uid, it.box))
            fail("uid " + std::to_string(it.uid) + " gathered with a box it no longer has, and not logged");
    }
    if (phase_ == Phase::build)
        for (const auto& [uid, at] : live.where_)
            if (to_replay.count(uid) == 0 && gathered.count(uid) == 0)
                fail("live uid " + std::to_string(uid) + " was not gathered, and not logged");
}

void WideBvh::validate_tree(bool refitted) const {
    // The next tree of a rebuild is checked before its refit: its lanes may not enclose yet.
    auto fail = [refitted](const std::string& what) {
        broken_invariant("wbvh", (refitted ? "" : "next tree: ") + what);
    };
    if (refitted && !dirty_.empty()) fail("blocks not refitted after changes (commit missing)");
    const auto total = std::uint32_t(blocks_.size());
    std::uint32_t free_seen = 0;
    for (std::uint32_t b = free_; b != kNone; b = blocks_[b].parent) {
        if (b >= total) fail("free list points outside the block array");
        if (blocks_[b].count != 0) fail("block " + std::to_string(b) + " on the free list is in use");
        if (++free_seen > total) fail("free list has a cycle");
    }
    if (free_seen != free_count_)
        fail("free list holds " + std::to_string(free_seen) + " blocks, count says " + std::to_string(free_count_));
    std::uint32_t reached = 0, leaves = 0;
    std::size_t objects = 0;
    auto is_unused = [](const Block& b, int k) {
        constexpr float inf = std::numeric_limits<float>::infinity();
        for (int a = 0; a < 3; ++a)
            if (b.bound[a][k] != inf || b.bound[3 + a][k] != -inf) return false;
        return true;
    };
    if (root_ != kNone) {
        if (root_ >= total || blocks_[root_].parent != kNone || blocks_[root_].depth != 0)
            fail("root has a parent, a depth or is out of range");
        std::vector<std::uint32_t> stack{root_};
        while (!stack.empty()) {
            const std::uint32_t b = stack.back();
            stack.pop_back();
            if (++reached > total) fail("tree has a cycle");
            const Block& block = blocks_[b];
            const std::string name = "block " + std::to_string(b);
            if (block.count == 0 || block.count > kLanes) fail(name + " has " + std::to_string(block.count) + " lanes");
            if (block.depth > max_depth_) fail(name + " is deeper than the stack allows");
            if (refitted && block.dirty) fail(name + " is still marked for the refit");
            for (int k = block.count; k < kLanes; ++k)
                if (!is_unused(block, k)) fail(name + ": an unused lane holds a box that segments can meet");
            if (block.leaf) {
                ++leaves;
                for (int k = 0; k < block.count; ++k) {
                    ++objects;
                    const Uid uid = block.ref[k];
                    auto it = where_.find(uid);
                    if (it == where_.end() || it->second != b * kLanes + std::uint32_t(k))
                        fail("uid " + std::to_string(uid) + " in " + name + " is not where the uid index says");
                    const Aabb box = block.box(k);
                    if (!(box.min.x <= box.max.x && box.min.y <= box.max.y && box.min.z <= box.max.z))
                        fail("uid " + std::to_string(uid) + " has min > max");
                }
                continue;
            }
            for (int k = 0; k < block.count; ++k) {
                const std::uint32_t c = block.ref[k];
                if (c >= total) fail(name + ": child out of range");
                const Block& child = blocks_[c];
                if (child.parent != b || child.lane_in_parent != k)
                    fail("block " + std::to_string(c) + " does not point back to lane " + std::to_string(k) + " of " +
                         name);
                if (child.depth != block.depth + 1) fail("block " + std::to_string(c) + " has a wrong depth");
                if (refitted && child.count > 0 && !block.box(k).contains(child.bounds()))
                    fail(name + " lane " + std::to_string(k) + " does not enclose its child");
                stack.push_back(c);
            }
        }
    }
    if (objects != where_.size())
        fail(std::to_string(where_.size()) + " live uids but " + std::to_string(objects) + " objects in the tree");
    if (leaves != leaves_)
        fail("leaf count says " + std::to_string(leaves_) + ", the tree has " + std::to_string(leaves));
    if (reached + free_seen != total)
        fail("blocks neither in the tree nor free: " + std::to_string(total - reached - free_seen));
    const double fresh = fresh_sah_sum();
    if (!(std::abs(fresh - sah_sum_) <= 1e-6 * std::max(std::abs(fresh), sah_largest_term_ * 1e-6) + 1e-300))
        fail("running SAH sum " + std::to_string(sah_sum_) + " differs from the tree's " + std::to_string(fresh));
}

}  // namespace rcb
