#pragma once
/// Hierarchical hash grid (thesis §4.3, after Jevans & Wyvill 1989): a top grid sized by eq. 4.2
/// whose crowded cells split into `subdivision`³ children down to `max_depth`, only non-empty cells
/// stored, found through one hash table keyed by (depth, cell). Rays run thesis Algorithm 2: the
/// 3D-DDA over the top grid, recursing into subdivided cells (common/grid.h); a closest-hit ray
/// stops at the first cell, at any level, entered after its best hit. Cells keep copies of
/// their objects' boxes in blocks of four, as in the uniform grid. Split and collapse rules derive
/// from integer cell ranges so insert, remove and check agree; memory, large-object and outlier
/// guards keep it bounded on hostile scenes. docs/structures.md has the rules and the reasons.

#include <algorithm>
#include <array>
#include <cstdint>
#include <tuple>
#include <unordered_map>
#include <vector>

#include "accel/interface/params.h"
#include "accel/interface/hit_policy.h"
#include "accel/interface/structure.h"
#include "accel/grid/grid.h"
#include "accel/common/query_scratch.h"

namespace rcb {

/// Open-addressing hash table from 64-bit keys to 32-bit values: linear probing, backward-shift
/// deletion (no tombstones; Knuth TAOCP vol. 3, algorithm 6.4R), load factor ≤ 1/2.
class CellTable {
public:
    static constexpr std::uint64_t kEmpty = ~std::uint64_t(0);
    static constexpr std::uint32_t kNone = ~std::uint32_t(0);

    std::uint32_t find(std::uint64_t key) const {
        if (keys_.empty()) return kNone;
        for (std::size_t i = home(key);; i = (i + 1) & mask_) {
            if (keys_[i] == key) return values_[i];
            if (keys_[i] == kEmpty) return kNone;
        }
    }
    /// Where a lookup of `key` starts reading (the cache model's read; nullptr when empty).
    const std::uint64_t* home_slot(std::uint64_t key) const { return keys_.empty() ? nullptr : &keys_[home(key)]; }
    void insert(std::uint64_t key, std::uint32_t value);
    void erase(std::uint64_t key);
    void clear();
    std::size_t size() const { return size_; }
    std::size_t memory_bytes() const {
        return keys_.capacity() * sizeof(std::uint64_t) + values_.capacity() * sizeof(std::uint32_t);
    }
    template <class F>
    void for_each(F&& f) const {
        for (std::size_t i = 0; i < keys_.size(); ++i)
            if (keys_[i] != kEmpty) f(keys_[i], values_[i]);
    }

private:
    std::size_t home(std::uint64_t key) const { return std::size_t((key * 0x9E3779B97F4A7C15ull) >> shift_); }
    void grow();

    std::vector<std::uint64_t> keys_;
    std::vector<std::uint32_t> values_;
    std::size_t mask_ = 0;
    int shift_ = 64;
    std::size_t size_ = 0;
};

class HashGrid : public StructureBase<HashGrid, StampScratch> {
public:
    struct Params {
        double amp = 1.0;
        int max_depth = 2;
        int max_capacity = 16;
        int subdivision = 2;
        int max_entries_per_object = 16;
        bool entries_guard = true;
        bool outlier_guard = true;
        int max_cells = grid::kDefaultMaxCells;
        int cast_threads = 1;
        static constexpr auto fields() {
            return std::tuple{
                Field{"amp", &Params::amp, 0.01, 16.0, "top-level cells = objects × amp (eq. 4.2)", kLogScale},
                Field{"max_depth", &Params::max_depth, 0, 6, "levels of subdivision below the top grid"},
                Field{"max_capacity", &Params::max_capacity, 1, 256,
                      "objects a leaf holds before it splits (collapse at half)", kLogScale},
                Field{"subdivision", &Params::subdivision, 2, 4, "children per axis when a cell splits"},
                Field{"max_entries_per_object", &Params::max_entries_per_object, 2, 256,
                      "memory guard: a split that would make the cells hold more than this many object entries per "
                      "object (over max(objects, objects at build, 64)) is refused",
                      kNotTuned},
                Field{"entries_guard", &Params::entries_guard, 0.0, 1.0,
                      "apply the max_entries_per_object memory guard (off: splits are limited by max_depth and a "
                      "fixed ceiling of 512 entries per object that keeps the work bounded; stats "
                      "guards_off.entries_guard counts the splits and descents the guard would have refused, "
                      "guards_off.entries_ceiling those the ceiling refused)",
                      kNotTuned},
                Field{"outlier_guard", &Params::outlier_guard, 0.0, 1.0,
                      "top grid over the central 99% of the objects per axis when the full bounds are over 8x larger "
                      "(exact either way; stats guards_off.outlier_guard says when it would have trimmed)",
                      kNotTuned},
                Field{"max_cells", &Params::max_cells, 0, 1 << 20,
                      "large-object guard: an object overlapping more than this many top-grid cells is kept in one "
                      "list that every ray tests once (0: off, unbounded: scene-sized boxes sit in every top cell; "
                      "stats guards_off.max_cells counts the objects the default would have listed)",
                      kNotTuned},
                cast_threads_field<Params>()};
        }
    };

    /// Finest-lattice cells per axis (20 bits per coordinate in the hash key).
    static constexpr int kMaxFineRes = 1 << 20;
    /// Entries per object with entries_guard off. Without any limit, crowded surfaces split down to
    /// max_depth (subdivision^(2·max_depth) cells per top cell: a deep grid ran for minutes on the
    /// hard scenes); the ceiling bounds that work and lies above the guard's range (2..256), so
    /// turning the guard off still shows what it prevents.
    static constexpr int kEntriesCeiling = 512;

    HashGrid() : HashGrid(Params{}) {}
    explicit HashGrid(const Params& p);

    void build(std::span<const Object> objects) override;
    void insert(const Object& object) override;
    void remove(Uid uid) override;
    void move(const Object& object) override;
    std::size_t size() const override { return slot_.size(); }
    std::uint64_t writes() const override { return writes_ + large_.writes(); }
    std::size_t memory_bytes() const override;
    nlohmann::json stats() const override;
    void check() const override;

    // The traversal interface of StructureBase.
    void prepare() {}
    void fit(StampScratch& scratch) const { scratch.fit(entries_.size(), false); }
    template <class Count, class Visit>
    void traverse(const Segment& s, Count& count, Visit&& visit, StampScratch& scratch) const;

private:
    struct Entry {
        Aabb box;
        Uid uid = 0;
    };
    struct Cell {
        BlockCell own;  ///< objects stored here, with copies of their boxes (box_block.h)
        std::uint64_t key = CellTable::kEmpty;
        std::uint32_t count = 0;  ///< distinct objects stored here or below
        bool subdivided = false;
    };
    static_assert(sizeof(Cell) <= 48, "a cell stays within 48 bytes (the ray reads it)");
    using Index = grid::Index;

    static std::uint64_t key_of(int depth, const Index& i) {
        return (std::uint64_t(depth) << 60) | (std::uint64_t(i[0]) << 40) | (std::uint64_t(i[1]) << 20) |
               std::uint64_t(i[2]);
    }
    /// The object's cell range at `depth`, from its finest range.
    grid::CellRange range_at(const grid::CellRange& fine, int depth) const;
    /// The children of cell `i` at `depth` (cells at depth + 1).
    grid::CellRange children_of(const Index& i) const;
    bool covers(const grid::CellRange& fine, int depth, const Index& i) const;
    /// The object's range at depth + 1 clamped into the children of `i`.
    grid::CellRange child_range(const grid::CellRange& fine, int depth, const Index& i) const;

    std::uint32_t find_or_create(int depth, const Index& i);
    void delete_cell(std::uint32_t cell);
    void insert_into(int depth, const Index& i, std::uint32_t slot, const grid::CellRange& fine);
    void remove_from(int depth, const Index& i, std::uint32_t slot, const grid::CellRange& fine);
    /// Gives `slot`'s box copy in every cell that holds it (below cell `i` at `depth`) the box `box`.
    void rewrite_in(int depth, const Index& i, std::uint32_t slot, const grid::CellRange& fine, const Aabb& box);
    /// The objects of a cell: add one, take them all out (the cell is left empty), put a list in.
    void own_push(std::uint32_t cell, std::uint32_t slot) {
        cells_[cell].own.push(entries_[slot].box, slot);
        ++writes_;
    }
    std::vector<std::uint32_t> take_own(std::uint32_t cell);
    void set_own(std::uint32_t cell, const std::vector<std::uint32_t>& slots);
    void split(std::uint32_t cell, int depth, const Index& i);
    /// A limit on entries_total_ of `per_object` entries per object.
    std::size_t budget(int per_object) const {
        return std::size_t(per_object) * std::max({slot_.size(), build_objects_, std::size_t(64)});
    }
    /// The memory guard's limit on entries_total_.
    std::size_t entry_budget() const { return budget(params_.max_entries_per_object); }
    /// The limit in force: the guard's, or with the guard off the ceiling.
    std::size_t active_budget() const { return params_.entries_guard ? entry_budget() : budget(kEntriesCeiling); }
    void collapse(std::uint32_t cell, int depth, const Index& i);
    void gather_and_delete_children(int depth, const Index& i, std::vector<std::uint32_t>& out);
    template <class Ctx>
    bool visit_cell(Ctx& ctx, int depth, const Index& c, double t_in, double t_out) const;

    Params params_;
    std::vector<grid::Lattice> lat_;  // per depth
    std::vector<int> pow_;            // subdivision^k
    bool clamped_ = false;
    bool trimmed_ = false;  ///< the outlier guard trimmed the top grid
    CellTable table_;
    std::vector<Cell> cells_;
    std::vector<std::uint32_t> free_cells_;
    std::vector<Entry> entries_;
    std::vector<std::uint32_t> free_slots_;
    std::unordered_map<Uid, std::uint32_t> slot_;
    std::size_t entries_total_ = 0;  ///< sum of the cells' `own` sizes
    std::size_t build_objects_ = 0;
    /// Per cell: a leaf tries to split only with at least this many objects (see the memory guard);
    /// beside cells_, not in it, so the cells a ray reads stay 40 bytes.
    std::vector<std::uint32_t> retry_at_;
    BlockList large_;  ///< the large-object guard's objects (in no cell)
    // Guard reports since the build (stats).
    std::size_t refused_splits_ = 0;
    std::size_t guard_collapses_ = 0;
    std::size_t unguarded_overruns_ = 0;  ///< entries_guard off: its refusals and collapses that did not happen
    std::size_t ceiling_refusals_ = 0;    ///< entries_guard off: splits and descents the ceiling refused
    bool would_trim_ = false;             ///< the outlier guard is off and would have trimmed the top grid
    /// writes(), with the large list's own count: one per cell entry pushed, erased or rewritten at
    /// any depth (a split's or collapse's moved entries included), per cell created in or removed
    /// from the table.
    std::uint64_t writes_ = 0;
    /// The large-object guard's test, on the object's top-grid range.
    bool is_large(const grid::CellRange& top) const {
        return params_.max_cells > 0 && grid::cell_count(top) > std::size_t(params_.max_cells);
    }
};

template <class Count, class Visit>
struct HashGridQuery {
    using VisitType = Visit;
    SegmentSlabs slabs;
    Vec3d p0, d;
    std::uint32_t stamp;
    std::uint32_t* stamps;  // the thread's mailboxes (query_scratch.h)
    Count& count;
    Visit& visit;
};

template <class Ctx>
bool HashGrid::visit_cell(Ctx& ctx, int depth, const Index& c, double t_in, double t_out) const {
    // Closest hit (hit_policy.h): a cell entered after the best hit so far, within float rounding
    // (grid::closest_cutoff), ends the whole walk, at the top grid and in a children walk alike.
    // Exact: an object is in the large list (tested before the walk) or, at every level it
    // reaches, in each cell its box overlaps (in the cell's own list or in the children it
    // overlaps), so the object entered at t sits in the cell holding its entry point at some
    // depth; the walks go front to back, a children walk within its parent's [t_in, t_out], so
    // that cell is entered no later than t and every cell after a cut-off one no earlier than it.
    // A cell entered exactly at the limit is still visited: a tie there goes to the smaller uid
    // (docs/accuracy.md, "Query kinds"). All and any hits have no limit: this compiles away.
    if constexpr (HasTLimit<typename Ctx::VisitType>) {
        if (t_in > grid::closest_cutoff(visit_limit(ctx.visit))) return false;
    }
    ctx.count.traversal();
    const std::uint64_t key = key_of(depth, c);
    if constexpr (std::remove_reference_t<decltype(ctx.count)>::enabled) {  // the counting pass only
        if (const std::uint64_t* slot = table_.home_slot(key)) ctx.count.reads(slot, sizeof *slot);
    }
    const std::uint32_t id = table_.find(key);
    if (id == CellTable::kNone) return true;
    const Cell& cell = cells_[id];
    ctx.count.reads(&cell, sizeof cell);
    ctx.count.box_tests(cell.own.size);
    // Four boxes per slab test (box_block.h), as in the uniform grid. An object in several cells is
    // tested in each and reported once: checking the stamp only on a hit saves a hard-to-predict
    // branch per object.
    for (const BoxBlock& b : cell.own.blocks) {
        float tn[BoxBlock::kLanes];
        ctx.count.reads(&b, sizeof b);
        for (unsigned hits = b.test_at<std::remove_reference_t<decltype(ctx.count)>>(ctx.slabs, tn); hits;
             hits &= hits - 1) {
            const int lane = __builtin_ctz(hits);
            const std::uint32_t slot = b.slot[lane];
            if (ctx.stamps[slot] == ctx.stamp) {
                ctx.count.duplicates();
                continue;
            }
            ctx.stamps[slot] = ctx.stamp;
            ctx.count.hits();
            if (!ctx.visit(entries_[slot].uid, tn[lane])) return false;
        }
    }
    if (!cell.subdivided) return true;
    // Algorithm 2: the cell's box becomes the world of a DDA over its children, over the part of
    // the segment inside the cell.
    const int child = depth + 1;
    const grid::CellRange r = children_of(c);
    const grid::Lattice& lat = lat_[child];
    Index start;
    for (int a = 0; a < 3; ++a) start[a] = std::clamp(lat.index(a, ctx.p0[a] + t_in * ctx.d[a]), r.lo[a], r.hi[a]);
    return grid::walk(lat, ctx.p0, ctx.d, r, start, t_in, t_out, ctx.count,
                      [&](const Index& ci, double ti, double to) { return visit_cell(ctx, child, ci, ti, to); });
}

template <class Count, class Visit>
void HashGrid::traverse(const Segment& s, Count& count, Visit&& visit, StampScratch& scratch) const {
    HashGridQuery<Count, std::remove_reference_t<Visit>> ctx{SegmentSlabs(s),
                                                             s.p0.as<double>(),
                                                             s.p1.as<double>() - s.p0.as<double>(),
                                                             scratch.next(),
                                                             scratch.stamps.data(),
                                                             count,
                                                             visit};
    // Large objects first: each is in this list only, so it is tested once and needs no stamp.
    count.box_tests(large_.size());
    for (const BoxBlock& b : large_.cell().blocks) {
        float tn[BoxBlock::kLanes];
        count.reads(&b, sizeof b);
        for (unsigned hits = b.test_at<Count>(ctx.slabs, tn); hits; hits &= hits - 1) {
            const int lane = __builtin_ctz(hits);
            count.hits();
            if (!visit(entries_[b.slot[lane]].uid, tn[lane])) return;
        }
    }
    const grid::Lattice& top = lat_[0];
    const grid::CellRange all{{0, 0, 0}, {top.res[0] - 1, top.res[1] - 1, top.res[2] - 1}};
    Index start;
    for (int a = 0; a < 3; ++a) start[a] = top.index(a, ctx.p0[a]);
    grid::walk(top, ctx.p0, ctx.d, all, start, 0.0, 1.0, count,
               [&](const Index& c, double ti, double to) { return visit_cell(ctx, 0, c, ti, to); });
}

}  // namespace rcb
