#include "accel/bvh/wide_bvh_build.h"

#include <algorithm>
#include <limits>

#include "accel/bvh/wide_bvh.h"

namespace rcb {

void WideBvhBuilder::begin(WideBvh& t) {
    t.clear_tree();
    // About one leaf per leaf_size objects and one inner node per (width − 1) blocks below.
    t.blocks_.reserve(items_.size() / std::size_t(t.params_.leaf_size) * 8 / 6 + 2);
    pending_.clear();
    opening_ = false;
    splitting_ = -1;
    build_work_ = 0;
    if (!items_.empty()) pending_.push_back({Range{0, std::uint32_t(items_.size())}, kNone, 0, 0});
}

void WideBvhBuilder::end(WideBvh& t) {
    t.grow_stack(t.max_depth_);
    t.total_after_build_ = t.total_sah();
    // The scratch is only needed again at the next rebuild: not held in between.
    std::vector<SahItem>().swap(items_);
    std::vector<Pending>().swap(pending_);
}

std::uint64_t WideBvhBuilder::step(WideBvh& t, std::uint64_t budget) {
    const WideBvh::Params& params = t.params_;
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
                const double a = sah_area<double>(parts_[i].box);
                if (pick < 0 || a > pick_area || (a == pick_area && parts_[i].n > parts_[pick].n))
                    pick = i, pick_area = a;
            }
            if (pick < 0) {
                finish_node(t);
                work += std::uint64_t(nparts_);
                continue;
            }
            start_split(pick);
        }
        work += split_step(params.bins, budget - work);
    }
    build_work_ += work;
    return work;
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

void WideBvhBuilder::finish_node(WideBvh& t) {
    const std::uint32_t b = t.allocate();
    WideBvh::Block& block = t.blocks_[b];
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

void WideBvhBuilder::make_leaf(WideBvh& t, const Pending& p) {
    const std::uint32_t b = t.allocate();
    WideBvh::Block& block = t.blocks_[b];
    block.leaf = true;
    block.depth = p.depth;
    block.count = std::uint8_t(p.range.n);
    ++t.leaves_;
    for (std::uint32_t i = 0; i < p.range.n; ++i) {
        const SahItem& it = items_[p.range.begin + i];
        block.set(int(i), it.box);
        block.ref[i] = it.id;
        t.where_.set(it.id, b * WideBvh::kLanes + i);
    }
    t.max_depth_ = std::max(t.max_depth_, int(p.depth));
    t.link(b, p.parent, p.lane);
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
    return items_.capacity() * sizeof(SahItem) + pending_.capacity() * sizeof(Pending) + sah_.memory_bytes();
}

}  // namespace rcb
