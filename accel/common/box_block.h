#pragma once
/// A grid cell's objects in blocks of four boxes, each axis' bounds side by side, so that one block
/// is one 4-wide slab test (SSE on x86-64, a scalar loop elsewhere) and the cell's walk costs one
/// branch per block plus one per hit, not one or two per object. Measured on uni-l (14 021 objects,
/// 22 cells and 79 box tests per ray): a per-object loop mispredicted about 100 branches per ray.
///
/// Unused lanes hold the empty box (min +inf, max -inf), which no finite segment hits, so a block is
/// always tested whole. The test is SegmentSlabs::clip exactly: the same float operations in the
/// same order, and MAXPS/MINPS return their second operand when either is NaN, as
/// max_ignoring_nan(lo, tn) does.

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "accel/model/counters.h"
#include "core/base/geometry.h"

#if defined(__SSE2__)
#include <immintrin.h>
#endif

namespace rcb {

struct alignas(16) BoxBlock {
    static constexpr int kLanes = 4;
    float min[3][kLanes];
    float max[3][kLanes];
    std::uint32_t slot[kLanes];

    void set(int lane, const Aabb& b, std::uint32_t s) {
        for (int a = 0; a < 3; ++a) min[a][lane] = b.min[a], max[a][lane] = b.max[a];
        slot[lane] = s;
    }
    void clear(int lane) {
        for (int a = 0; a < 3; ++a)
            min[a][lane] = std::numeric_limits<float>::infinity(),
            max[a][lane] = -std::numeric_limits<float>::infinity();
        slot[lane] = 0;
    }
    Aabb box(int lane) const {
        return {{min[0][lane], min[1][lane], min[2][lane]}, {max[0][lane], max[1][lane], max[2][lane]}};
    }

    /// Lanes that hold an object (unused lanes hold the empty box).
    unsigned used() const {
        unsigned mask = 0;
        for (int k = 0; k < kLanes; ++k)
            if (min[0][k] <= max[0][k]) mask |= 1u << k;
        return mask;
    }
    /// test() at the traversal policy's level: at the candidate level (counters.h) every object in
    /// the block, with t_near 0.
    template <class Policy>
    unsigned test_at(const SegmentSlabs& s, float t_near[kLanes]) const {
        if constexpr (Policy::candidates) {
            for (int k = 0; k < kLanes; ++k) t_near[k] = 0;
            return used();
        } else {
            return test(s, t_near);
        }
    }
    /// The slab test of the four lanes: bit k of the result is set when lane k is hit, and
    /// t_near[k] is its entry parameter.
    unsigned test(const SegmentSlabs& s, float t_near[kLanes]) const {
#if defined(__SSE2__)
        __m128 tn = _mm_setzero_ps(), tf = _mm_set1_ps(1.0f);
        for (int a = 0; a < 3; ++a) {
            const __m128 o = _mm_set1_ps(s.origin[a]), inv = _mm_set1_ps(s.inv[a]);
            const __m128 n = _mm_load_ps(s.near_is_max[a] ? max[a] : min[a]);
            const __m128 f = _mm_load_ps(s.near_is_max[a] ? min[a] : max[a]);
            tn = _mm_max_ps(_mm_mul_ps(_mm_sub_ps(n, o), inv), tn);
            tf = _mm_min_ps(_mm_mul_ps(_mm_sub_ps(f, o), inv), tf);
        }
        _mm_storeu_ps(t_near, tn);
        return unsigned(_mm_movemask_ps(_mm_cmple_ps(tn, tf)));
#else
        unsigned mask = 0;
        for (int k = 0; k < kLanes; ++k) {
            float tf;
            if (s.clip(box(k), t_near[k], tf)) mask |= 1u << k;
        }
        return mask;
#endif
    }
};

/// One grid cell: `size` objects in the first lanes of `blocks`.
struct BlockCell {
    std::vector<BoxBlock> blocks;
    std::uint32_t size = 0;

    void push(const Aabb& box, std::uint32_t slot) {
        const int lane = int(size % BoxBlock::kLanes);
        if (lane == 0) {
            blocks.emplace_back();
            for (int k = 0; k < BoxBlock::kLanes; ++k) blocks.back().clear(k);
        }
        blocks.back().set(lane, box, slot);
        ++size;
    }
    /// Empties the cell, keeping its capacity.
    void clear() {
        blocks.clear();
        size = 0;
    }
    /// Removes `slot` (present): the last lane moves into its place.
    void erase(std::uint32_t slot) { erase_at(index_of(slot)); }
    /// Removes the object at index `i` (< size): the last lane moves into its place.
    void erase_at(std::uint32_t i) {
        const std::uint32_t last = size - 1;
        BoxBlock& lb = blocks[last / BoxBlock::kLanes];
        const int ll = int(last % BoxBlock::kLanes);
        set(i, lb.box(ll), lb.slot[ll]);
        lb.clear(ll);
        if (ll == 0) blocks.pop_back();
        --size;
    }
    /// Gives `slot` (present) the box `box`.
    void rewrite(std::uint32_t slot, const Aabb& box) { set(index_of(slot), box, slot); }
    void set(std::uint32_t i, const Aabb& box, std::uint32_t slot) {
        blocks[i / BoxBlock::kLanes].set(int(i % BoxBlock::kLanes), box, slot);
    }
    /// What is wrong with the lanes' layout ("" when nothing): one block per four objects, and no
    /// unused lane that a segment could hit.
    std::string defect() const {
        if (blocks.size() != (size + BoxBlock::kLanes - 1) / BoxBlock::kLanes)
            return "cell blocks do not match its size";
        for (std::uint32_t i = size; i < blocks.size() * BoxBlock::kLanes; ++i)
            if (box(i).min.x <= box(i).max.x) return "an unused lane holds a box that segments can hit";
        return "";
    }
    std::uint32_t slot(std::uint32_t i) const { return blocks[i / BoxBlock::kLanes].slot[i % BoxBlock::kLanes]; }
    Aabb box(std::uint32_t i) const { return blocks[i / BoxBlock::kLanes].box(int(i % BoxBlock::kLanes)); }

private:
    std::uint32_t index_of(std::uint32_t slot) const {
        std::uint32_t i = 0;
        while (this->slot(i) != slot) ++i;
        return i;
    }
};

/// A BlockCell with a slot → index table, so that erase and rewrite are O(1) however many objects
/// it holds: the grids' list of large objects (uniform_grid.h), which every ray tests once.
class BlockList {
public:
    bool contains(std::uint32_t slot) const { return slot < index_.size() && index_[slot] != kAbsent; }
    void insert(const Aabb& box, std::uint32_t slot) {
        if (index_.size() <= slot) index_.resize(std::size_t(slot) + 1, kAbsent);
        index_[slot] = cell_.size;
        cell_.push(box, slot);
        ++writes_;
    }
    /// Removes `slot` (present); the last object takes its index.
    void erase(std::uint32_t slot) {
        const std::uint32_t i = index_[slot], moved = cell_.slot(cell_.size - 1);
        cell_.erase_at(i);
        index_[moved] = i;
        index_[slot] = kAbsent;
        ++writes_;
    }
    void rewrite(std::uint32_t slot, const Aabb& box) {
        cell_.set(index_[slot], box, slot);
        ++writes_;
    }
    void clear() {
        cell_ = BlockCell{};
        index_.clear();
    }
    const BlockCell& cell() const { return cell_; }
    std::uint32_t size() const { return cell_.size; }
    /// Inserts, erases and rewrites since construction (kept through clear(): the owner's
    /// Structure::writes() adds it, and that count only grows).
    std::uint64_t writes() const { return writes_; }
    std::size_t memory_bytes() const {
        return cell_.blocks.capacity() * sizeof(BoxBlock) + index_.capacity() * sizeof(std::uint32_t);
    }
    /// What is wrong with the list ("" when nothing): the cell's layout, and an index that does not
    /// point at its slot.
    std::string defect() const {
        if (std::string d = cell_.defect(); !d.empty()) return d;
        std::uint32_t indexed = 0;
        for (std::size_t s = 0; s < index_.size(); ++s) {
            if (index_[s] == kAbsent) continue;
            ++indexed;
            if (index_[s] >= cell_.size || cell_.slot(index_[s]) != s) return "large-object index is stale";
        }
        return indexed == cell_.size ? "" : "large-object list and its index differ in size";
    }

private:
    static constexpr std::uint32_t kAbsent = ~std::uint32_t(0);
    BlockCell cell_;
    std::uint64_t writes_ = 0;
    std::vector<std::uint32_t> index_;
};

}  // namespace rcb
