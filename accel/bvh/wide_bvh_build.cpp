#include "accel/bvh/wide_bvh_build.h"

#include <algorithm>
#include <limits>

#include "accel/bvh/wide_bvh.h"

namespace rcb {

void WideBvhBuilder::begin(WideBvh& t) {
    t.clear_tree();
    // About one leaf per leaf_size objects and one inner node per (width − 1) blocks below.
    t.blocks_.reserve(items_.size() / std::size_t(t.params_.leaf_size) * 8 / 6 + 2);
    // Binary leaves hold about a third of leaf_size objects, and a binary tree has one inner node
    // fewer than leaves.
    nodes_.reserve(6 * items_.size() / std::size_t(t.params_.leaf_size) + 2);
    pending_.clear();
    nodes_.clear();
    prices_.clear();
    pick_.clear();
    leaf_size_ = std::uint32_t(t.params_.leaf_size);
    // The binary tree splits on to half a leaf, so that the collapse chooses the leaves: any
    // subtree of at most leaf_size objects.
    leaf_split_ = (leaf_size_ + 1) / 2;
    emit_.clear();
    splitting_ = -1;
    splitting_node_ = kNone;
    build_work_ = 0;
    phase_ = items_.empty() ? Phase::done : Phase::binary;
    if (!items_.empty()) pending_.push_back({Range{0, std::uint32_t(items_.size())}, kNone, 0});
}

void WideBvhBuilder::end(WideBvh& t) {
    t.grow_stack(t.max_depth_);
    t.total_after_build_ = t.total_sah();
    // The scratch is only needed again at the next rebuild: not held in between.
    std::vector<SahItem>().swap(items_);
    std::vector<Pending>().swap(pending_);
    std::vector<Node>().swap(nodes_);
    std::vector<double>().swap(prices_);
    std::vector<std::uint8_t>().swap(pick_);
    std::vector<Emit>().swap(emit_);
}

std::uint64_t WideBvhBuilder::step(WideBvh& t, std::uint64_t budget) {
    const WideBvh::Params& params = t.params_;
    std::uint64_t work = 0;
    while (work < budget && phase_ != Phase::done) {
        if (phase_ == Phase::binary)
            work += binary_step(params.bins, budget - work);
        else if (phase_ == Phase::price)
            work += price_step(params.width, budget - work);
        else
            work += emit_step(t, budget - work);
    }
    build_work_ += work;
    return work;
}

std::uint64_t WideBvhBuilder::binary_step(int bins, std::uint64_t budget) {
    std::uint64_t work = 0;
    while (work < budget) {
        if (splitting_ < 0) {
            if (pending_.empty()) {  // the binary tree is complete: price it, children first
                phase_ = Phase::price;
                price_cursor_ = std::uint32_t(nodes_.size());
                break;
            }
            const Pending p = pending_.back();
            pending_.pop_back();
            const auto i = std::uint32_t(nodes_.size());
            nodes_.push_back(Node{p.range});
            if (p.parent != kNone && p.side == 1) nodes_[p.parent].right = i;  // the left is p.parent + 1
            ++work;
            if (p.range.n <= leaf_split_) continue;
            parts_[0] = p.range;
            nparts_ = 1;
            splitting_node_ = i;
            start_split(0);
        }
        work += split_step(bins, budget - work);
        if (splitting_ < 0) {  // split: the left part next (depth first)
            pending_.push_back({parts_[1], splitting_node_, 1});
            pending_.push_back({parts_[0], splitting_node_, 0});
        }
    }
    return work;
}

std::uint64_t WideBvhBuilder::price_step(int width, std::uint64_t budget) {
    if (pick_.empty()) pick_.assign(nodes_.size() * std::size_t(width), 0);
    std::uint64_t work = 0;
    while (work < budget && price_cursor_ > 0) {
        price(--price_cursor_, width);
        work += std::uint64_t(width);
    }
    if (price_cursor_ == 0) {
        prices_.clear();
        phase_ = Phase::emit;
        emit_.push_back({0, kNone, 0, 0});
    }
    return work;
}

void WideBvhBuilder::price(std::uint32_t i, int width) {
    // Ylitie et al. 2017's recurrence, in expected block visits (the area of a block's box over the
    // root's; a leaf's lanes are one test like an inner block's, so its objects add nothing):
    // cost(n, 1) is n as one root, a leaf when it holds at most leaf_size objects, else an inner
    // block whose `width` lanes hold its children's forests; cost(n, j) the cheaper of at most
    // j − 1 roots and the two children's forests sharing j roots. On ties the more roots: the
    // fuller parent (zero-area subtrees too). Nodes come in reverse order of creation, a mirrored
    // post-order, so the children's prices are the top two of prices_ (the left one on top).
    const Node& n = nodes_[i];
    const std::size_t w = std::size_t(width);
    std::uint8_t* pick = pick_.data() + i * w;
    const double area = sah_area<double>(n.range.box);
    if (n.leaf()) {  // every price that of the leaf, every pick 0
        prices_.insert(prices_.end(), w, area);
        return;
    }
    std::array<double, kWideLanes> a, b;
    std::copy_n(prices_.end() - std::ptrdiff_t(w), w, a.begin());
    std::copy_n(prices_.end() - std::ptrdiff_t(2 * w), w, b.begin());
    prices_.resize(prices_.size() - 2 * w);
    std::array<double, kWideLanes + 1> shared{};
    std::array<std::uint8_t, kWideLanes + 1> split{};
    for (int j = 2; j <= width; ++j) {
        double best = std::numeric_limits<double>::infinity();
        for (int k = 1; k < j; ++k) {
            const double v = a[std::size_t(k) - 1] + b[std::size_t(j - k) - 1];
            if (v < best) best = v, split[std::size_t(j)] = std::uint8_t(k);
        }
        shared[std::size_t(j)] = best;
    }
    std::array<double, kWideLanes> c;
    const bool leaf = n.range.n <= leaf_size_;  // at least as cheap as an inner block: leaves cost alike
    c[0] = leaf ? area : area + shared[w];
    pick[0] = leaf ? 0 : split[w];
    for (int j = 2; j <= width; ++j) {
        const bool share = shared[std::size_t(j)] <= c[std::size_t(j) - 2];
        c[std::size_t(j) - 1] = share ? shared[std::size_t(j)] : c[std::size_t(j) - 2];
        pick[j - 1] = share ? split[std::size_t(j)] : 0;
    }
    prices_.insert(prices_.end(), c.begin(), c.begin() + std::ptrdiff_t(w));
}

int WideBvhBuilder::collapse(std::uint32_t i, int width, std::uint32_t* roots) const {
    // The forests traced from the picks top down: a node given j roots takes fewer while its pick
    // says so, is one root at j = 1 (or a leaf), else shares j between its children.
    struct Slot {
        std::uint32_t node;
        int roots;
    };
    std::array<Slot, kWideLanes> stack;
    const std::size_t w = std::size_t(width);
    int top = 0, count = 0;
    const int k = pick_[i * w];
    stack[std::size_t(top++)] = {nodes_[i].right, width - k};
    stack[std::size_t(top++)] = {i + 1, k};
    while (top > 0) {
        auto [m, j] = stack[std::size_t(--top)];
        const Node& x = nodes_[m];
        while (j >= 2 && !x.leaf() && pick_[m * w + std::size_t(j) - 1] == 0) --j;
        if (j == 1 || x.leaf()) {
            roots[count++] = m;
            continue;
        }
        const int km = pick_[m * w + std::size_t(j) - 1];
        stack[std::size_t(top++)] = {x.right, j - km};
        stack[std::size_t(top++)] = {m + 1, km};
    }
    return count;
}

std::uint64_t WideBvhBuilder::emit_step(WideBvh& t, std::uint64_t budget) {
    std::uint64_t work = 0;
    while (work < budget && !emit_.empty()) {
        const Emit e = emit_.back();
        emit_.pop_back();
        work += write_block(t, e);
    }
    if (emit_.empty()) phase_ = Phase::done;
    return work;
}

std::uint64_t WideBvhBuilder::write_block(WideBvh& t, const Emit& e) {
    const Node& x = nodes_[e.node];
    const std::size_t w = std::size_t(t.params_.width);
    const std::uint32_t b = t.allocate();
    WideBvh::Block& block = t.blocks_[b];
    block.depth = e.depth;
    t.max_depth_ = std::max(t.max_depth_, int(e.depth));
    if (pick_[e.node * w] == 0) {  // a leaf (price())
        block.leaf = true;
        block.count = std::uint8_t(x.range.n);
        ++t.leaves_;
        for (std::uint32_t i = 0; i < x.range.n; ++i) {
            const SahItem& it = items_[x.range.begin + i];
            block.set(int(i), it.box);
            block.ref[i] = it.id;
            t.where_.set(it.id, b * WideBvh::kLanes + i);
        }
        t.link(b, e.parent, e.lane);
        return x.range.n;
    }
    std::array<std::uint32_t, kWideLanes> roots;
    const int count = collapse(e.node, t.params_.width, roots.data());
    block.count = std::uint8_t(count);
    for (int j = 0; j < count; ++j) block.set(j, nodes_[roots[std::size_t(j)]].range.box);
    t.link(b, e.parent, e.lane);
    // Children in reverse, so that the first is written next (depth first, in lane order).
    for (int j = count - 1; j >= 0; --j)
        emit_.push_back({roots[std::size_t(j)], b, std::uint16_t(e.depth + 1), std::uint8_t(j)});
    return std::uint64_t(count);
}

double WideBvhBuilder::inner_fill(const WideBvh& t) {
    std::uint64_t inner = 0, children = 0;
    for (const WideBvh::Block& b : t.blocks_)
        if (b.count != 0 && !b.leaf) ++inner, children += b.count;  // a free block has count 0
    return inner ? double(children) / double(inner) : 0.0;
}

void WideBvhBuilder::start_split(int part) {
    splitting_ = part;
    stage_ = Stage::centroid_bounds;
    cursor_ = parts_[std::size_t(part)].begin;
    cbox_ = Aabb::empty();
}

std::uint64_t WideBvhBuilder::split_step(int bins, std::uint64_t budget) {
    const Range r = parts_[std::size_t(splitting_)];
    const std::uint32_t end = r.begin + r.n;
    SahItem* const items = items_.data();
    const std::uint32_t i = cursor_;
    const std::uint32_t stop = budget >= end - i ? end : i + std::uint32_t(budget);
    const std::uint64_t work = stop - i;
    if (stage_ == Stage::centroid_bounds) {
        cbox_ = grow_centroid_bounds(cbox_, items + i, items + stop);
        cursor_ = stop;
        if (stop < end) return work;
        if (!sah_.begin(cbox_, bins)) {
            split_fallback();
            return work + r.n;
        }
        stage_ = Stage::binning;
        cursor_ = r.begin;
        return work;
    }
    if (stage_ == Stage::binning) {
        sah_.add(items + i, items + stop);
        cursor_ = stop;
        if (stop < end) return work;
        split_ = sah_.choose(r.n);
        if (!split_.found()) {
            split_fallback();
            return work + r.n;
        }
        stage_ = Stage::partition;
        partition_.begin(r.begin, split_);
        return work;
    }
    // Partition: the items of the left part's bins to [begin, begin + split_.left); resumable.
    const std::uint64_t done = partition_.step(sah_, split_, items, budget);
    if (!partition_.done()) return done;
    // The parts' boxes are the unions of their bins'.
    const auto [left, right] = sah_.sides(split_);
    divide(split_.left, left, right);
    return done;
}

void WideBvhBuilder::split_fallback() {
    const Range r = parts_[std::size_t(splitting_)];
    SahItem* items = items_.data() + r.begin;
    // No axis binned: the centroids coincide (boxes nested around one centre, or duplicates).
    const bool coincide = !sah_.binned(0) && !sah_.binned(1) && !sah_.binned(2);
    const std::uint32_t half = coincide ? split_by_size<double>(items, r.n) : split_at_median(items, r.n, cbox_);
    Aabb left = Aabb::empty(), right = Aabb::empty();
    for (std::uint32_t i = 0; i < r.n; ++i) (i < half ? left : right) = merge(i < half ? left : right, items[i].box);
    divide(half, left, right);
}

void WideBvhBuilder::divide(std::uint32_t left, const Aabb& left_box, const Aabb& right_box) {
    const Range r = parts_[std::size_t(splitting_)];
    parts_[std::size_t(nparts_++)] = Range{r.begin + left, r.n - left, right_box};
    parts_[std::size_t(splitting_)] = Range{r.begin, left, left_box};
    splitting_ = -1;
}

std::uint32_t WideBvhBuilder::split(int bins, SahItem* items, std::uint32_t n) {
    // The build's split run whole on these items: no build is in progress in this tree when one of
    // its leaves splits (builds run to their end, or in the next tree of a progressive rebuild).
    items_.assign(items, items + n);
    parts_[0] = Range{0, n};
    nparts_ = 1;
    start_split(0);
    while (splitting_ >= 0) split_step(bins, std::numeric_limits<std::uint64_t>::max());
    std::copy(items_.begin(), items_.end(), items);
    items_.clear();
    return parts_[0].n;
}

std::size_t WideBvhBuilder::memory_bytes() const {
    return items_.capacity() * sizeof(SahItem) + pending_.capacity() * sizeof(Pending) +
           nodes_.capacity() * sizeof(Node) + prices_.capacity() * sizeof(double) + pick_.capacity() +
           emit_.capacity() * sizeof(Emit) + sah_.memory_bytes();
}

}  // namespace rcb
