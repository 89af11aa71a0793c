#include "accel/bvh/wide_bvh.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

#include <unistd.h>

namespace rcb {

namespace {

/// Half the surface area in double (boxes near the coordinate limit overflow float); 0 for the
/// empty box.
double area(const Aabb& b) { return sah_area<double>(b); }

/// The centre without overflow near the coordinate limit.
Vec3 centroid(const Aabb& b) { return WideBvhBuilder::centroid(b); }

/// A move's share of a change for the rebuild trigger (Params::rebuild_after): how far its
/// farthest face moved, in units of the object's longest edge (before or after, the longer),
/// capped at one. A step much smaller than the object leaves the tree's partition as good as it
/// was (the refit's growth is what rebuild_ratio watches); a move by its own size or more is as
/// stale as a removal and an insertion. In double: boxes near the coordinate limit overflow float.
double move_share(const Aabb& from, const Aabb& to) {
#if defined(__AVX2__)
    // The three axes at once, in double as below (one move each frame for every moving body: the
    // scalar loop was half of a move's instructions). The fourth lane repeats z. Exact: the
    // differences and maxima are the scalar ones, for boxes without NaN.
    auto wide = [](const Vec3& v) { return _mm256_cvtps_pd(_mm_setr_ps(v.x, v.y, v.z, v.z)); };
    const __m256d f_lo = wide(from.min), f_hi = wide(from.max), t_lo = wide(to.min), t_hi = wide(to.max);
    const __m256d sign = _mm256_set1_pd(-0.0);
    __m256d m = _mm256_max_pd(_mm256_andnot_pd(sign, _mm256_sub_pd(t_lo, f_lo)),
                              _mm256_andnot_pd(sign, _mm256_sub_pd(t_hi, f_hi)));
    __m256d e = _mm256_max_pd(_mm256_sub_pd(f_hi, f_lo), _mm256_sub_pd(t_hi, t_lo));
    m = _mm256_max_pd(m, _mm256_permute2f128_pd(m, m, 1));
    e = _mm256_max_pd(e, _mm256_permute2f128_pd(e, e, 1));
    const double shift = _mm256_cvtsd_f64(_mm256_max_pd(m, _mm256_permute_pd(m, 5)));
    const double size = std::max(0.0, _mm256_cvtsd_f64(_mm256_max_pd(e, _mm256_permute_pd(e, 5))));
#else
    double shift = 0, size = 0;
    for (int a = 0; a < 3; ++a) {
        shift = std::max({shift, std::abs(double(to.min[a]) - double(from.min[a])),
                          std::abs(double(to.max[a]) - double(from.max[a]))});
        size = std::max({size, double(from.max[a]) - double(from.min[a]), double(to.max[a]) - double(to.min[a])});
    }
#endif
    if (shift == 0) return 0.0;
    return shift < size ? shift / size : 1.0;  // a point's (size 0) or a far jump: a whole change
}

/// A move or remove of a uid the tree does not hold: the caller's error, as std::out_of_range (as
/// the map's at() threw before the flat index).
[[noreturn, gnu::cold, gnu::noinline]] void absent_uid(const char* what, Uid uid) {
    throw std::out_of_range(std::string("wbvh: ") + what + " of uid " + std::to_string(uid) + ", not in the tree");
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
#if defined(__AVX2__)
    // Each row's 8 lanes reduced in three steps (halves, pairs of pairs, pairs): min and max are
    // exact, so this is the scalar loop's answer for boxes without NaN (which no box holds).
    auto reduce = [](__m256 v, auto op) {
        v = op(v, _mm256_permute2f128_ps(v, v, 1));
        v = op(v, _mm256_shuffle_ps(v, v, 0x4e));
        v = op(v, _mm256_shuffle_ps(v, v, 0xb1));
        return _mm256_cvtss_f32(v);
    };
    auto lo = [](__m256 x, __m256 y) { return _mm256_min_ps(x, y); };
    auto hi = [](__m256 x, __m256 y) { return _mm256_max_ps(x, y); };
    for (int a = 0; a < 3; ++a) {
        b.min[a] = reduce(_mm256_load_ps(bound[a]), lo);
        b.max[a] = reduce(_mm256_load_ps(bound[3 + a]), hi);
    }
#else
    for (int a = 0; a < 3; ++a) {
        float lo = bound[a][0], hi = bound[3 + a][0];
        for (int k = 1; k < kLanes; ++k) lo = std::min(lo, bound[a][k]), hi = std::max(hi, bound[3 + a][k]);
        b.min[a] = lo, b.max[a] = hi;
    }
#endif
    return b;
}

WideBvh::WideBvh() : WideBvh(Params{}) {}

WideBvh::WideBvh(const Params& p)
    : params_(p),
      push_(parse_choice<Push>(kPushChoices, p.push, "wbvh push")),
      queue_mode_(parse_choice<Queue>(kQueueChoices, p.queue_moves, "wbvh queue_moves")) {
    set_cast_threads(p.cast_threads);
    if (p.threads > 1) update_arena_ = std::make_unique<CastArena>(p.threads);
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
    dirty_repeats_ |= block.dirty;  // listed in dirty_: listed again if reused and marked
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
    // A rebuild in progress is dropped, and queued moves: the new contents replace everything.
    rebuild_.reset();
    pending_.clear();
    pending_inserts_.clear();
    changes_ = 0;
    weighted_changes_ = age_ = 0;
    commits_ = 0;
    std::vector<SahItem>& items = builder_.items();
    items.clear();
    items.reserve(objects.size());
    Uid max_uid = 0;
    for (const Object& o : objects) {
        items.push_back({o.box, centroid(o.box), o.uid});
        max_uid = std::max(max_uid, o.uid);
    }
    where_.clear();
    where_.reserve(objects.size(), max_uid);
    rebuilds_ = splits_ = reinserts_ = 0;
    builder_.begin(*this);
    builder_.step(*this, std::numeric_limits<std::uint64_t>::max());
    builder_.end(*this);
    rebuild_.estimate(builder_.work(), objects.size());
    resolve_queue();
}

void WideBvh::rebuild() {
    std::vector<SahItem>& items = builder_.items();
    items.clear();
    items.reserve(where_.size());
    for (const Block& b : blocks_)
        if (b.leaf)
            for (int k = 0; k < b.count; ++k) items.push_back({b.box(k), centroid(b.box(k)), Uid(b.ref[k])});
    builder_.begin(*this);
    builder_.step(*this, std::numeric_limits<std::uint64_t>::max());
    builder_.end(*this);
    ++rebuilds_;
    ++counts_.rebuilds;
    counts_.rebuild_work += builder_.work();
    age_ = 0;
    commits_ = 0;
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

// ---- changes ----

std::uint32_t WideBvh::choose_leaf(const Aabb& box, std::uint32_t* path) const {
    std::uint32_t b = root_;
    if (path) *path++ = b;
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
        if (path) *path++ = b;
    }
    return b;
}

void WideBvh::insert(const Object& o) {
    if (!pending_.empty()) flush();  // the queued moves (and the inserts queued before them) first
    ++changes_;
    weighted_changes_ += 1;
    rebuild_.log_change(o.uid);
    if (update_arena_ && root_ != kNone)
        pending_inserts_.push_back(o);  // its leaf is looked for on the threads (apply_inserts())
    else
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
        where_.set(o.uid, root_ * kLanes);
        grow_stack(0);
        return;
    }
    insert_into(choose_leaf(o.box), o);
}

void WideBvh::insert_into(std::uint32_t leaf, const Object& o) {
    Block& block = blocks_[leaf];
    update_work_ += block.depth + 1u;  // the descent that chose the leaf
    if (block.count == kLanes) {
        split_leaf(leaf, o);
        return;
    }
    const int k = block.count++;
    block.set(k, o.box);
    block.ref[k] = o.uid;
    ++writes_;
    where_.set(o.uid, leaf * kLanes + std::uint32_t(k));
    if (leaf != root_) {  // its weight grew by one
        const double a = area(blocks_[block.parent].box(block.lane_in_parent));
        sah_sum_ += a;
        sah_largest_term_ = std::max(sah_largest_term_, a);
    }
    mark(leaf);
}

void WideBvh::split_leaf(std::uint32_t leaf, const Object& o) {
    ++splits_;
    ++counts_.splits;
    // The leaf's lane in its parent (and the parent's other lanes), or the root, change.
    note_changed(leaf);
    if (blocks_[leaf].parent != kNone) note_changed(blocks_[leaf].parent);
    std::array<SahItem, kLanes + 1> nine;
    {
        const Block& block = blocks_[leaf];
        for (int k = 0; k < kLanes; ++k) {
            nine[std::size_t(k)] = {block.box(k), centroid(block.box(k)), Uid(block.ref[k])};
            rebuild_.log_relocation(Uid(block.ref[k]));
        }
    }
    nine[kLanes] = {o.box, centroid(o.box), o.uid};
    where_.set(o.uid, 0);
    const std::uint32_t m = builder_.split(params_.bins, nine.data(), kLanes + 1);
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
    auto fill = [&](std::uint32_t b, const SahItem* items, std::uint32_t count) {
        Block& block = blocks_[b];
        for (int k = 0; k < kLanes; ++k) block.clear(k);
        block.leaf = true;
        block.count = std::uint8_t(count);
        for (std::uint32_t i = 0; i < count; ++i) {
            block.set(int(i), items[i].box);
            block.ref[i] = items[i].id;
            where_.set(items[i].id, b * kLanes + i);
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
    flush();
    ++changes_;
    weighted_changes_ += 1;
    rebuild_.log_change(uid);
    remove_object(uid);
}

void WideBvh::remove_object(Uid uid) {
    const std::uint32_t at = where_.find(uid);
    if (at == WideBvhIndex::kAbsent) absent_uid("remove", uid);
    const std::uint32_t b = at / kLanes;
    const int k = int(at % kLanes);
    where_.erase(uid);
    Block& block = blocks_[b];
    const int last = block.count - 1;
    if (k != last) {
        block.set(k, block.box(last));
        block.ref[k] = block.ref[last];
        ++writes_;
        where_.set(Uid(block.ref[k]), b * kLanes + std::uint32_t(k));
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

void WideBvh::reinsert(Uid uid, const Aabb& box) {
    ++reinserts_;
    ++counts_.reinserts;
    weighted_changes_ += 1;  // a removal and an insertion
    remove_object(uid);
    insert_object(Object(uid, box));
}

void WideBvh::move(const Object& o) {
    if (!queue_ && !pending_inserts_.empty()) apply_inserts();  // applied at once: after them
    std::uint32_t at = where_.find(o.uid);
    if (at == WideBvhIndex::kAbsent && !pending_inserts_.empty()) {  // inserted, not yet applied
        apply_inserts();
        at = where_.find(o.uid);
    }
    if (at == WideBvhIndex::kAbsent) absent_uid("move", o.uid);
    ++changes_;
    rebuild_.log_change(o.uid);
    if (queue_)
        pending_.push_back({o.uid, o.box});
    else
        apply_move(at, o.uid, o.box);
}

void WideBvh::apply_moves() {
    if (update_arena_ && pending_.size() >= kParallelUpdate) {
        apply_moves_parallel();
        return;
    }
    constexpr std::size_t kAhead = 8;  // moves in flight: a few hundred instructions' window
    const std::size_t n = pending_.size();
    for (std::size_t i = 0; i < n; ++i) {
        if (i + kAhead < n) {
            const std::uint32_t at = where_.find(pending_[i + kAhead].uid);
            if (at != WideBvhIndex::kAbsent) {  // the 256-byte leaf, for writing
                const char* leaf = reinterpret_cast<const char*>(&blocks_[at / kLanes]);
                for (int line = 0; line < int(sizeof(Block)); line += 64) __builtin_prefetch(leaf + line, 1);
            }
        }
        apply_move(where_.find(pending_[i].uid), pending_[i].uid, pending_[i].box);
    }
    pending_.clear();
}

bool WideBvh::leaves_leaf(std::uint32_t b, const Aabb& box) const {
    if (!params_.reinsert || b == root_) return false;
    const Block& leaf = blocks_[b];
    const Aabb lane = blocks_[leaf.parent].box(leaf.lane_in_parent);
    const Vec3 c = centroid(box);
    return !(lane.min.x <= c.x && c.x <= lane.max.x && lane.min.y <= c.y && c.y <= lane.max.y && lane.min.z <= c.z &&
             c.z <= lane.max.z);
}

void WideBvh::apply_move(std::uint32_t at, Uid uid, const Aabb& box) {
    const std::uint32_t b = at / kLanes;
    if (leaves_leaf(b, box)) {
        reinsert(uid, box);
        return;
    }
    const int k = int(at % kLanes);
    // Only rebuild_after reads the weight: without it a move is the lane's write alone.
    if (params_.rebuild_after > 0) weighted_changes_ += move_share(blocks_[b].box(k), box);
    blocks_[b].set(k, box);
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
    // (check_tree checks both), so the parent of a block at `level` belongs to level − 1.
    if (refit_levels_.size() < std::size_t(max_depth_) + 1) refit_levels_.resize(std::size_t(max_depth_) + 1);
    if (update_arena_ && dirty_repeats_) unique_dirty();  // a parallel level lists each block once
    for (const std::uint32_t d : dirty_)
        if (blocks_[d].dirty) refit_levels_[blocks_[d].depth].push_back(d);  // a released block is unmarked
    dirty_.clear();
    for (std::size_t level = refit_levels_.size(); level-- > 0;) {
        std::vector<std::uint32_t>& queue = refit_levels_[level];
        std::vector<std::uint32_t>* up = level > 0 ? &refit_levels_[level - 1] : nullptr;
        if (update_arena_ && queue.size() >= kParallelUpdate)
            refit_level_parallel(queue, up);
        else
            for (const std::uint32_t c : queue)
                if (blocks_[c].dirty) count_refit(refit_block(c), up);  // listed twice if released and reused
        queue.clear();
    }
}

// ---- the update on several threads (Params::threads) ----
//
// Engines thread the refit and the build, not the single change: Embree's BVHNRefitter::refit
// (kernels/bvh/bvh_refit.cpp) refits the subtrees below a fixed depth in a parallel_for and the
// few nodes above them on one thread; its builders (BVHNBuilderMorton, the SAH builders) split the
// work by subtree. Jolt's BroadPhaseQuadTree runs UpdatePrepare (the next tree's build) as a job
// beside the simulation and UpdateFinalize (the swap) on the caller. Here the refit runs level by
// level, as refit() does: the blocks of a level are independent (each writes its own lane of its
// parent, a level up), so threads take chunks of a level's queue, and the calling thread then adds
// the SAH terms, counts and queues the parents in the queue's order. The queued moves (a physics
// frame's) are independent too as long as no reinsertion touches their leaf; apply_moves_parallel()
// looks them up, checks and weighs them on the threads, and rewrites their lanes there, while the
// calling thread does everything whose order shows (the marks, the sums, the reinsertions) in the
// queue's order. The tree, its answers and every counter are those of one thread, bit for bit
// (the floating-point sums are added in the same order).

template <class F>
void WideBvh::in_chunks(std::size_t n, F&& f) {
    // Four chunks per thread, taken one at a time (CastArena::run): a thread held up by cache misses
    // takes fewer. The cut does not change any result.
    const std::size_t chunks = std::size_t(update_arena_->threads()) * 4, len = (n + chunks - 1) / chunks;
    update_arena_->run(chunks, [&](std::size_t c, int) {
        const std::size_t b = std::min(n, c * len), e = std::min(n, b + len);
        if (b < e) f(b, e);
    });
}

void WideBvh::unique_dirty() {
    // Each block at its first listing, the flag cleared meanwhile; released blocks (unmarked) drop.
    std::size_t kept = 0;
    for (const std::uint32_t d : dirty_)
        if (blocks_[d].dirty) blocks_[d].dirty = false, dirty_[kept++] = d;
    dirty_.resize(kept);
    for (const std::uint32_t d : dirty_) blocks_[d].dirty = true;
    dirty_repeats_ = false;
}

void WideBvh::refit_level_parallel(std::vector<std::uint32_t>& queue, std::vector<std::uint32_t>* up) {
    const std::size_t n = queue.size();
    ++parallel_steps_;
    refit_records_.resize(n);
    // A block of this level is read and unmarked by one thread only, and writes one lane of its
    // parent (a level up, which no thread reads now): no two threads write the same bytes.
    in_chunks(n, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) refit_records_[i] = refit_block(queue[i]);
    });
    for (std::size_t i = 0; i < n; ++i) count_refit(refit_records_[i], up);  // in the queue's order
}

WideBvh::RefitRecord WideBvh::refit_block(std::uint32_t c) {
    Block& block = blocks_[c];
    RefitRecord r;
    block.dirty = false;
    if (c == root_) return r;
    const Aabb box = block.bounds();
    Block& parent = blocks_[block.parent];
    const int lane = block.lane_in_parent;
    const Aabb old = parent.box(lane);
    r.parent = block.parent;
    r.state = 1;
    if (box == old) return r;
    // set_lane's work without its sums (count_refit adds them in order): both boxes are in use
    // (never empty), and the weight is this block's.
    const double w = weight(c);
    r.before = area(old) * w, r.after = area(box) * w;
    parent.set(lane, box);
    r.state = 2;
    return r;
}

void WideBvh::count_refit(const RefitRecord& r, std::vector<std::uint32_t>* up) {
    if (r.state == 0) return;
    ++refit_blocks_;
    ++counts_.refit_blocks;
    ++writes_;
    if (r.state == 1) return;
    sah_sum_ += r.after - r.before;
    sah_largest_term_ = std::max({sah_largest_term_, r.before, r.after});
    ++writes_;
    ++refit_lanes_;
    ++counts_.refit_lanes;
    Block& parent = blocks_[r.parent];
    if (!parent.dirty) {
        parent.dirty = true;
        up->push_back(r.parent);
    }
}

/// A move that stays in its leaf rewrites one lane and marks the leaf; a reinsertion changes the
/// leaf it leaves and the one it enters (lanes, slots, counts), and a leaf split or a leaf that
/// empties changes inner lanes. So the plan walks the queue on the calling thread, reading the tree
/// only: the first move of a uid moved twice, or a reinsertion that would split or empty a leaf,
/// ends it (that move and the rest go as apply_moves() does them); before it, the leaves each
/// reinsertion leaves and enters (choose_leaf() on the inner lanes, which nothing before it
/// changes) are marked touched. Every other move's slot, check and weight, taken from the tree as
/// it was before the queue, are then what the sequential pass would find.
std::size_t WideBvh::plan_moves() {
    const std::size_t n = pending_.size();
    slot_seen_.assign((blocks_.size() * kLanes + 63) / 64, 0);
    block_touched_.assign((blocks_.size() + 63) / 64, 0);
    leaf_count_.resize(blocks_.size());
    auto count_of = [&](std::uint32_t leaf) -> std::uint8_t& {
        std::uint64_t& word = block_touched_[leaf / 64];
        const std::uint64_t bit = std::uint64_t(1) << (leaf % 64);
        if (!(word & bit)) word |= bit, leaf_count_[leaf] = blocks_[leaf].count;
        return leaf_count_[leaf];
    };
    for (std::size_t i = 0; i < n; ++i) {
        const std::uint32_t at = move_slot_[i];
        std::uint64_t& seen = slot_seen_[at / 64];
        const std::uint64_t bit = std::uint64_t(1) << (at % 64);
        if (seen & bit) return i;  // the uid moved twice
        seen |= bit;
        if (!move_reinserts_[i]) continue;
        const std::uint32_t from = at / kLanes;
        if (count_of(from) == 1) return i;  // its leaf would empty
        --count_of(from);
        std::uint8_t& into = count_of(choose_leaf(pending_[i].box));
        if (into == kLanes) return i;  // the leaf would split
        ++into;
    }
    return n;
}

void WideBvh::apply_moves_parallel() {
    const std::size_t n = pending_.size();
    ++parallel_steps_;
    const bool weigh = params_.rebuild_after > 0;
    move_slot_.resize(n);
    move_reinserts_.resize(n);
    if (weigh) move_weight_.resize(n);
    // 1. Slots, checks and weights against the tree before the queue (reads only).
    in_chunks(n, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
            const PendingMove& m = pending_[i];
            const std::uint32_t at = where_.find(m.uid), b = at / kLanes;
            move_slot_[i] = at;
            move_reinserts_[i] = leaves_leaf(b, m.box);
            if (weigh && !move_reinserts_[i]) move_weight_[i] = move_share(blocks_[b].box(int(at % kLanes)), m.box);
        }
    });
    // 2. The plan (plan_moves()): before `stop`, a move is the threads' when it stays in an
    // untouched leaf.
    const std::size_t stop = plan_moves();
    auto threads_own = [&](std::size_t i) {
        const std::uint32_t b = move_slot_[i] / kLanes;
        return !move_reinserts_[i] && !(block_touched_[b / 64] >> (b % 64) & 1);
    };
    // 3. Their lanes, on the threads: distinct lanes of leaves that nothing else before `stop`
    // reads or writes.
    in_chunks(stop, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i)
            if (threads_own(i)) {
                const std::uint32_t at = move_slot_[i];
                blocks_[at / kLanes].set(int(at % kLanes), pending_[i].box);
            }
    });
    // 4. In the queue's order: their weights, writes and marks, and the other moves whole.
    constexpr std::size_t kAhead = 8;
    for (std::size_t i = 0; i < n; ++i) {
        if (i + kAhead < n) {  // the leaf's line with its mark, or the whole leaf from `stop` on
            const std::uint32_t at = i + kAhead < stop ? move_slot_[i + kAhead] : where_.find(pending_[i + kAhead].uid);
            const char* leaf = reinterpret_cast<const char*>(&blocks_[at / kLanes]);
            for (int line = i + kAhead < stop ? 192 : 0; line < int(sizeof(Block)); line += 64)
                __builtin_prefetch(leaf + line, 1);
        }
        if (i < stop && threads_own(i)) {
            if (weigh) weighted_changes_ += move_weight_[i];
            ++writes_;
            mark(move_slot_[i] / kLanes);
        } else {
            apply_move(where_.find(pending_[i].uid), pending_[i].uid, pending_[i].box);
        }
    }
    pending_.clear();
}

/// The leaves of the queued inserts are looked for on the threads first, each recording the blocks
/// it read (choose_leaf() reads only inner blocks' lanes, counts and children, and the leaf flag).
/// Then, in the queue's order on the calling thread, each is inserted as insert_object() does; a
/// leaf split changes its leaf's parent (or the root), and an insert whose recorded path passes a
/// block changed so looks for its leaf again. Nothing else in an insert changes what choose_leaf()
/// reads, so every insert goes to the leaf the sequential pass would choose.
void WideBvh::apply_inserts() {
    const std::size_t n = pending_inserts_.size();
    if (!update_arena_ || n < kParallelInserts) {
        for (const Object& o : pending_inserts_) insert_object(o);
        pending_inserts_.clear();
        return;
    }
    ++parallel_steps_;
    const std::size_t stride = std::size_t(max_depth_) + 1;  // a path holds depth + 1 blocks
    insert_paths_.resize(n * stride);
    in_chunks(n, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
            std::uint32_t* path = &insert_paths_[i * stride];
            std::fill_n(path, stride, kNone);
            choose_leaf(pending_inserts_[i].box, path);
        }
    });
    inner_changed_.assign((blocks_.size() + 63) / 64, 0);
    for (std::size_t i = 0; i < n; ++i) {
        const std::uint32_t* path = &insert_paths_[i * stride];
        std::uint32_t leaf = kNone;
        bool valid = true;
        for (std::size_t d = 0; d < stride && path[d] != kNone; ++d) {
            leaf = path[d];
            valid &= !(inner_changed_[leaf / 64] >> (leaf % 64) & 1);
        }
        const Object& o = pending_inserts_[i];
        insert_into(valid ? leaf : choose_leaf(o.box), o);
    }
    inner_changed_.clear();
    pending_inserts_.clear();
}

void WideBvh::commit() {
    flush();
    refit_blocks_ = refit_lanes_ = 0;
    refit();
    resolve_queue();
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
    ++commits_;
    rebuild_.commit(*this, changes, weighted);
    counts_.rebuild_work += rebuild_.work();
}

// ---- rebuild trigger (the rebuild itself: wide_bvh_rebuild.cpp) ----

bool WideBvh::rebuild_due() const {
    if (root_ == kNone) return false;
    const double ratio = params_.rebuild_ratio;
    if (ratio > 0 && (ratio <= 1 || sah_growth() > ratio)) return true;
    if (params_.rebuild_every > 0 && commits_ >= std::uint32_t(params_.rebuild_every)) return true;
    return params_.rebuild_after > 0 && age_ >= params_.rebuild_after * double(where_.size());
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

std::uint64_t WideBvh::fingerprint() const {
    // FNV-1a over the fields (not the padding) of the blocks in use, in block order.
    std::uint64_t h = 0xcbf29ce484222325ull;
    auto add = [&h](std::uint64_t word) { h = (h ^ word) * 0x100000001b3ull; };
    add(root_), add(free_), add(free_count_), add(blocks_.size());
    for (const Block& b : blocks_) {
        if (b.count == 0) continue;
        for (const auto& row : b.bound)
            for (const float f : row) add(std::bit_cast<std::uint32_t>(f));
        for (const std::uint32_t r : b.ref) add(r);
        add(b.parent), add(b.depth), add(b.lane_in_parent), add(b.count), add(b.leaf), add(b.dirty);
    }
    return h;
}

std::size_t WideBvh::l2_bytes() {
    static const std::size_t bytes = [] {
        const long b = sysconf(_SC_LEVEL2_CACHE_SIZE);
        return b > 0 ? std::size_t(b) : std::size_t(1) << 20;
    }();
    return bytes;
}

/// A build's work units (an item binned, bounded or partitioned, an object written to a leaf;
/// wide_bvh_rebuild.h) per block a descent reads, by their times: the unit in which update_work()
/// counts the rebuilds' work beside the descents. Without it a frame of a progressive rebuild,
/// which spends rebuild_speed objects' share of a build per change, shows no more work than one
/// without, while it takes several times as long (docs/model.md, "Footprint of an update").
constexpr std::uint64_t kBuildUnitsPerDescentBlock = 16;

std::uint64_t WideBvh::update_work() const {
    // The sum of the units since construction divided once, so that a frame's growth loses no
    // remainder to rounding.
    return update_work_ + counts_.rebuild_work / kBuildUnitsPerDescentBlock;
}

std::size_t WideBvh::memory_bytes() const {
    return blocks_.capacity() * sizeof(Block) + where_.memory_bytes() + dirty_.capacity() * sizeof(std::uint32_t) +
           pending_.capacity() * sizeof(PendingMove) + refit_levels_bytes() + scratch_bytes() +
           refit_records_.capacity() * sizeof(RefitRecord) + move_slot_.capacity() * sizeof(std::uint32_t) +
           move_reinserts_.capacity() + move_weight_.capacity() * sizeof(double) +
           (slot_seen_.capacity() + block_touched_.capacity() + inner_changed_.capacity()) * sizeof(std::uint64_t) +
           leaf_count_.capacity() + pending_inserts_.capacity() * sizeof(Object) +
           insert_paths_.capacity() * sizeof(std::uint32_t) + builder_.memory_bytes() + rebuild_.memory_bytes() +
           sizeof(*this);
}

nlohmann::json WideBvh::stats() const {
    nlohmann::json stats = {{"sah_cost", sah_cost()}, {"sah_growth", sah_growth()},
                            {"depth", depth()},       {"nodes", blocks_.size() - free_count_},
                            {"leaves", leaves_},      {"rebuilds", rebuilds_},
                            {"leaf_splits", splits_}, {"reinserts", reinserts_}};
    // Children per inner block (of `width`): how full the collapse (wide_bvh_build.h) left them.
    stats["inner_fill"] = WideBvhBuilder::inner_fill(*this);
    // The weighted changes since the live tree's objects were gathered, per object: a rebuild
    // starts at commit once this reaches rebuild_after.
    stats["rebuild_age"] = where_.empty() ? 0.0 : age_ / double(where_.size());
    stats["rebuild_commits"] = commits_;  // commits with changes since then (Params::rebuild_every)
    // The last commit's refit: blocks whose box it computed (each at most once), and the lanes of
    // their parents it rewrote (with any refit a query's prepare ran after it).
    stats["refit_blocks"] = refit_blocks_;
    stats["refit_lanes"] = refit_lanes_;
    rebuild_.add_stats(stats);
    return stats;
}

void WideBvh::check() const {
    check_tree(true);
    rebuild_.check(*this);
}

void WideBvh::check_tree(bool refitted) const {
    // The next tree of a rebuild is checked before its refit: its lanes may not enclose yet.
    auto fail = [refitted](const std::string& what) {
        broken_invariant("wbvh", (refitted ? "" : "next tree: ") + what);
    };
    if (refitted && !dirty_.empty()) fail("blocks not refitted after changes (commit missing)");
    if (!pending_.empty() || !pending_inserts_.empty()) fail("moves or inserts not applied (commit missing)");
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
                    if (where_.find(uid) != b * kLanes + std::uint32_t(k))
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
