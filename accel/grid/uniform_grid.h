#pragma once
/// Uniform grid (thesis §4.2): the world box cut into equal cells sized by eq. 4.1; an object is
/// stored in every cell its box overlaps, and a ray walks the cells it crosses with the 3D-DDA
/// (thesis Algorithm 1, common/grid.h). Cells keep copies of their objects' boxes in blocks of four
/// (common/box_block.h); duplicate hits are dropped with per-query stamps. Guards keep it exact and
/// bounded on hostile scenes: unbounded border cells, an outlier trim of the lattice, a list for
/// objects larger than `max_cells` cells, and a cap on the cell count. docs/structures.md has the
/// details and the reasons. The outlier and large-object guards can be switched off (to measure
/// what they prevent); the grid is then unbounded on such scenes, and stats() names under
/// "guards_off" what the guard at its default would have done.

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <tuple>
#include <unordered_map>
#include <vector>

#include "accel/interface/params.h"
#include "accel/interface/structure.h"
#include "accel/common/box_block.h"
#include "accel/grid/grid.h"
#include "accel/common/query_scratch.h"

namespace rcb {

class UniformGrid : public StructureBase<UniformGrid, StampScratch> {
public:
    struct Params {
        // 4: what `rcbench tune experiments/tune-grids.json` finds on irreg-m and irreg-l (within 3%
        // of the best on both) and close to uni-l's best (16); the blocks of four make a cell of
        // several objects cheap to test.
        double density = 4.0;
        bool thesis_reset = false;
        bool outlier_guard = true;
        int max_cells = grid::kDefaultMaxCells;
        int cast_threads = 1;
        static constexpr auto fields() {
            return std::tuple{
                Field{"density", &Params::density, 0.1, 64.0,
                      "objects per cell in eq. 4.1 (cells = objects / density; capped at 4 Mi cells)", kLogScale},
                Field{"max_cells", &Params::max_cells, 0, 1 << 20,
                      "large-object guard: an object overlapping more than this many cells is kept in one list that "
                      "every ray tests once (0: off, unbounded: an object then sits in every cell it overlaps, so "
                      "scene-sized or identical boxes cost objects x cells entries, and time per move and ray; "
                      "stats guards_off.max_cells counts the objects the default would have listed)",
                      kNotTuned},
                Field{"outlier_guard", &Params::outlier_guard, 0.0, 1.0,
                      "cover only the central 99% of the objects per axis when the full bounds are over 8x larger "
                      "(outliers go to the unbounded border cells; exact either way; off: one far object can put "
                      "the scene into a few cells, stats guards_off.outlier_guard says when it would have trimmed)",
                      kNotTuned},
                Field{"thesis_reset", &Params::thesis_reset, 0.0, 1.0,
                      "avoid duplicate tests with the thesis' bool vector reset per ray (O(N) per ray) instead of "
                      "per-query stamps; for measuring the difference",
                      kNotTuned},
                cast_threads_field<Params>()};
        }
    };

    /// Upper bound on the number of cells (the memory guard; the cell size grows to respect it).
    static constexpr std::size_t kMaxCells = std::size_t(1) << 22;

    UniformGrid() : UniformGrid(Params{}) {}
    explicit UniformGrid(const Params& p) : params_(p) { set_cast_threads(p.cast_threads); }

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
    void fit(StampScratch& scratch) const { scratch.fit(entries_.size(), params_.thesis_reset); }
    template <class Count, class Visit>
    void traverse(const Segment& s, Count& count, Visit&& visit, StampScratch& scratch) const;

private:
    struct Entry {
        Aabb box;
        Uid uid = 0;
    };

    std::size_t cell_id(const std::array<int, 3>& i) const {
        return (std::size_t(i[2]) * std::size_t(lat_.res[1]) + std::size_t(i[1])) * std::size_t(lat_.res[0]) +
               std::size_t(i[0]);
    }
    void add_to_cells(std::uint32_t slot, const grid::CellRange& r);
    void rewrite_box(std::uint32_t slot, const grid::CellRange& r, const Aabb& box);
    void remove_from_cells(std::uint32_t slot, const grid::CellRange& r);
    /// The large-object guard's test (docs/structures.md).
    bool is_large(const grid::CellRange& r) const {
        return params_.max_cells > 0 && grid::cell_count(r) > std::size_t(params_.max_cells);
    }

    Params params_;
    grid::Lattice lat_;
    bool clamped_ = false;          ///< the cell cap enlarged the cells
    bool trimmed_ = false;          ///< the outlier guard trimmed the lattice
    bool would_trim_ = false;       ///< the outlier guard is off and would have trimmed it
    std::vector<BlockCell> cells_;  // cell → objects (copies of their boxes)
    BlockList large_;               // the large-object guard's objects (in no cell)
    std::vector<Entry> entries_;    // slot → object
    std::vector<std::uint32_t> free_slots_;
    std::unordered_map<Uid, std::uint32_t> slot_;  // uid → slot
    /// writes(), with the large list's own count: one per cell an object's entry is pushed into,
    /// erased from or rewritten in (what a change costs the cells it touches).
    std::uint64_t writes_ = 0;
};

template <class Count, class Visit>
void UniformGrid::traverse(const Segment& s, Count& count, Visit&& visit, StampScratch& scratch) const {
    const SegmentSlabs slabs(s);
    const Vec3d p0 = s.p0.as<double>(), d = s.p1.as<double>() - p0;
    std::array<int, 3> start;
    for (int a = 0; a < 3; ++a) start[a] = lat_.index(a, p0[a]);
    const bool reset = params_.thesis_reset;
    std::uint8_t* tested = scratch.tested.data();
    std::uint32_t* stamps = scratch.stamps.data();
    if (reset) std::fill(tested, tested + entries_.size(), std::uint8_t(0));
    const std::uint32_t stamp = reset ? 0 : scratch.next();
    // Large objects first: each is in this list only, so it is tested once and needs no stamp.
    count.box_tests(large_.size());
    for (const BoxBlock& b : large_.cell().blocks) {
        float tn[BoxBlock::kLanes];
        count.reads(&b, sizeof b);
        for (unsigned hits = b.test_at<Count>(slabs, tn); hits; hits &= hits - 1) {
            const int lane = __builtin_ctz(hits);
            count.hits();
            if (!visit(entries_[b.slot[lane]].uid, tn[lane])) return;
        }
    }
    const auto visit_cell = [&](const std::array<int, 3>& c, double t_in, double) {
        // Closest hit: the walk is front to back, and an object entered at t is stored in the cell
        // holding its entry point, which the walk enters no later than t (grid::kClosestSlack:
        // the lattice's double and the slab test's float round differently).
        if constexpr (HasTLimit<std::remove_cvref_t<Visit>>) {
            if (t_in > grid::closest_cutoff(visit_limit(visit))) return false;
        }
        count.traversal();
        const BlockCell& cell = cells_[cell_id(c)];
        count.reads(&cell, sizeof cell);
        count.box_tests(cell.size);
        for (const BoxBlock& b : cell.blocks) {
            float tn[BoxBlock::kLanes];
            count.reads(&b, sizeof b);
            for (unsigned hits = b.test_at<Count>(slabs, tn); hits; hits &= hits - 1) {
                const int lane = __builtin_ctz(hits);
                const std::uint32_t slot = b.slot[lane];
                // An object in several cells is tested in each (cheaper than a branch per object
                // to skip it) and reported once.
                if (reset) {
                    if (tested[slot]) {
                        count.duplicates();
                        continue;
                    }
                    tested[slot] = 1;
                } else {
                    if (stamps[slot] == stamp) {
                        count.duplicates();
                        continue;
                    }
                    stamps[slot] = stamp;
                }
                count.hits();
                if (!visit(entries_[slot].uid, tn[lane])) return false;
            }
        }
        return true;
    };
    grid::walk(lat_, p0, d, lat_.cells(), start, 0.0, 1.0, count, visit_cell);
}

}  // namespace rcb
