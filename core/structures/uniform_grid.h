#pragma once
/// Uniform grid (thesis §4.2): the world box cut into equal cells, cell size from eq. 4.1
/// (cells_per_dimension = (number / density)^(1/3), size = longest_edge / cells_per_dimension); an
/// object is stored in every cell its box overlaps; a ray walks the cells it crosses with the 3D-DDA
/// of Amanatides & Woo (1987, "A fast voxel traversal algorithm for ray tracing"), limited to the
/// segment (thesis Algorithm 1).
///
/// Choices beyond the thesis:
/// - Each cell keeps copies of its objects' boxes in blocks of four (box_block.h), tested four at a
///   time without a branch per object. An object in several cells is tested in each; duplicate
///   *hits* are dropped with per-query stamps (Amanatides & Woo's "mailboxes", checked only on a
///   hit): each object slot remembers the id of the last query that reported it, so nothing is
///   reset per ray. The thesis' O(N) reset of a bool vector per ray is kept behind `thesis_reset`
///   to measure the difference. On uni-l this layout casts 1.8x faster than one object at a time
///   with the stamp checked before each test (0.77 against 1.36 ms per 1000 rays).
/// - The border cells extend to infinity: an index is clamped into [0, res − 1] per axis, so an
///   object inserted or moved outside the initial bounds lands in the border cells it would overlap
///   if those were unbounded, and the DDA has no plane beyond the border (a segment outside the
///   grid walks the border cells). Always exact; only slower if much of the scene leaves the bounds.
/// - Outlier guard (`outlier_guard`, on by default): the lattice covers the central 99%
///   of the objects per axis when the full bounds are more than 8× larger (grid::lattice_bounds),
///   so a far outlier or a huge box around the scene does not make every cell huge. Exact either
///   way; without it a 10^6 outlier puts the whole scene into a few cells
///   (experiments/stability.json measures both).
/// - Large-object guard (`max_cells`, on by default): an object whose cell range holds more than
///   `max_cells` cells is kept once, in a list of large objects that every ray tests first, instead
///   of in each of its cells. Without it an object as large as the scene sits in every cell, is
///   tested in every cell a ray crosses and costs thousands of cell writes per move (cubes nested
///   around one centre, generator kind "nested"). With it an object costs at most max_cells
///   entries, and a ray tests it once per cell of it that the ray crosses: at most 3·∛max_cells − 2
///   times (7 for the default 27) for an object about as wide as it is long, at most max_cells
///   times for a row of cells the ray runs along. So long thin objects stay in their cells, where
///   most rays miss them, and an object as large as the scene goes to the list. Stats report
///   "large_objects".
/// - Memory guard: `density` has a bounded range and the total cell count is capped at
///   `kMaxCells` (the cell size grows instead), so no setting allocates without bound.
/// - Updates are incremental: a move that keeps the object's cell range only rewrites its box.

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <tuple>
#include <unordered_map>
#include <vector>

#include "core/params.h"
#include "core/structure.h"
#include "core/structures/box_block.h"

namespace rcb {

namespace grid {

/// An inclusive range of cell indices per axis.
struct CellRange {
    std::array<int, 3> lo{}, hi{};
    friend bool operator==(const CellRange&, const CellRange&) = default;
};

/// A lattice of cells of edge `size` from `origin`, `res` cells per axis, border cells unbounded.
struct Lattice {
    Vec3d origin;
    double size = 1;
    double inv_size = 1;
    std::array<int, 3> res{1, 1, 1};

    /// The cell holding coordinate x on `axis` (clamped: border cells extend to infinity).
    int index(int axis, double x) const {
        const double f = std::floor((x - origin[axis]) * inv_size);
        if (!(f >= 0)) return 0;  // also NaN-safe
        if (f >= double(res[axis] - 1)) return res[axis] - 1;
        return int(f);
    }
    CellRange range_of(const Aabb& b) const {
        CellRange r;
        for (int a = 0; a < 3; ++a) {
            r.lo[a] = index(a, b.min[a]);
            r.hi[a] = index(a, b.max[a]);
        }
        return r;
    }
    /// Position of the plane between cells k − 1 and k on `axis`.
    double plane(int axis, int k) const { return origin[axis] + double(k) * size; }
};

/// The 3D-DDA of Amanatides & Woo over `lat`, restricted to the cells of `range` and the segment
/// parameters [t0, t1], starting in cell `cur` (inside `range`). Calls
/// `cell(idx, t_in, t_out) -> bool` for every cell the segment crosses, in order; returns false as
/// soon as `cell` does. Plane crossings are computed afresh from the plane's index in double
/// precision (no accumulated t increments), and there is no plane beyond the lattice's border
/// (border cells are unbounded). Zero direction components never step.
template <class Cell>
bool walk(const Lattice& lat, const Vec3d& p0, const Vec3d& d, const CellRange& range, std::array<int, 3> cur,
          double t0, double t1, Cell&& cell) {
    constexpr double inf = std::numeric_limits<double>::infinity();
    int step[3];
    double next[3], inv[3];
    // In double, 1/d is finite for every nonzero float-derived d, and (plane − p0)·inv is accurate to
    // about 1e-16 relative: far inside the ground truth's tolerance.
    auto crossing = [&](int a) -> double {
        if (step[a] == 0) return inf;
        const int k = step[a] > 0 ? cur[a] + 1 : cur[a];  // the plane we leave the cell through
        if (k <= 0 || k >= lat.res[a]) return inf;        // unbounded border cell
        return (lat.plane(a, k) - p0[a]) * inv[a];
    };
    for (int a = 0; a < 3; ++a) {
        step[a] = d[a] > 0 ? 1 : (d[a] < 0 ? -1 : 0);
        inv[a] = step[a] != 0 ? 1.0 / d[a] : 0.0;
        next[a] = crossing(a);
    }
    double t_in = t0;
    for (;;) {
        // The axis of the nearest plane (ties to the lower axis), without branches: which axis
        // comes next is as good as random along a ray, so a branch here would mispredict often.
        int a = int(next[1] < next[0]);
        a = next[2] < next[a] ? 2 : a;
        const double t_cross = next[a];
        if (!cell(cur, t_in, std::min(t_cross, t1))) return false;
        if (!(t_cross <= t1)) return true;  // the segment ends in this cell
        cur[a] += step[a];
        if (cur[a] < range.lo[a] || cur[a] > range.hi[a]) return true;
        t_in = std::max(t_in, t_cross);
        next[a] = crossing(a);
    }
}

/// The live slots of a grid's object table (entries with a `uid`, a uid → slot index, a free list);
/// `fail(message)` unless the three agree.
template <class Entry, class Fail>
std::vector<std::uint8_t> live_slots(const std::vector<Entry>& entries,
                                     const std::unordered_map<Uid, std::uint32_t>& index,
                                     const std::vector<std::uint32_t>& free_slots, Fail&& fail) {
    std::vector<std::uint8_t> live(entries.size(), 0);
    for (const auto& [uid, slot] : index) {
        if (slot >= entries.size() || entries[slot].uid != uid)
            fail("uid index does not point at uid " + std::to_string(uid));
        if (live[slot]) fail("two uids share slot " + std::to_string(slot));
        live[slot] = 1;
    }
    if (index.size() + free_slots.size() != entries.size()) fail("slots are neither live nor free");
    for (std::uint32_t f : free_slots)
        if (f >= entries.size() || live[f]) fail("a free slot is live");
    return live;
}

/// The large-object list holds only live slots, each with its current box; `fail(message)` otherwise.
template <class Entry, class Fail>
void check_large_objects(const BlockList& large, const std::vector<Entry>& entries,
                         const std::vector<std::uint8_t>& live, Fail&& fail) {
    if (const std::string defect = large.defect(); !defect.empty()) fail(defect);
    for (std::uint32_t k = 0; k < large.size(); ++k) {
        const std::uint32_t slot = large.cell().slot(k);
        if (slot >= entries.size() || !live[slot])
            fail("stale entry (slot " + std::to_string(slot) + ") in the large-object list");
        if (!(large.cell().box(k) == entries[slot].box))
            fail("uid " + std::to_string(entries[slot].uid) + " has a stale box in the large-object list");
    }
}

/// Cells per axis for cells of edge `size` over `bounds` (at least 1).
std::array<int, 3> resolution(const Aabb& bounds, double size, int max_per_axis);

/// How far the full bounds may exceed the bounds of the central objects on an axis before the
/// outlier guard trims the lattice to the latter.
inline constexpr double kOutlierStretch = 8.0;

/// The box a lattice over `objects` covers (a unit box for no objects). Without the guard: the
/// union of the boxes. With the outlier guard: per axis, the box minima from their 0.5%
/// quantile to the box maxima's 99.5% quantile, when the full extent is more than
/// kOutlierStretch times that; one far object would otherwise make every cell huge and put the
/// rest of the scene into a few cells (a far outlier, a "stadium" box around a small cluster).
/// The objects outside land in the border cells, which extend to infinity: answers stay exact.
/// Sets `*trimmed` when the guard trimmed an axis.
Aabb lattice_bounds(std::span<const Object> objects, bool outlier_guard, bool* trimmed = nullptr);

/// The cells of the range `r`.
inline std::size_t cell_count(const CellRange& r) {
    return std::size_t(r.hi[0] - r.lo[0] + 1) * std::size_t(r.hi[1] - r.lo[1] + 1) * std::size_t(r.hi[2] - r.lo[2] + 1);
}

/// The grids' default for the large-object guard (UniformGrid::Params::max_cells, HashGrid's too):
/// a 3×3×3 block.
inline constexpr int kDefaultMaxCells = 27;

}  // namespace grid

class UniformGrid : public StructureBase<UniformGrid> {
public:
    struct Params {
        // 4: what `rcbench tune experiments/tune-grids.json` finds on irreg-m and irreg-l (within 3%
        // of the best on both) and close to uni-l's best (16); the blocks of four make a cell of
        // several objects cheap to test.
        double density = 4.0;
        bool thesis_reset = false;
        bool outlier_guard = true;
        int max_cells = grid::kDefaultMaxCells;
        static constexpr auto fields() {
            return std::tuple{
                Field{"density", &Params::density, 0.1, 64.0,
                      "objects per cell in eq. 4.1 (cells = objects / density; capped at 4 Mi cells)", true, true},
                Field{"max_cells", &Params::max_cells, 0, 1 << 20,
                      "large-object guard: an object overlapping more than this many cells is kept in one list that "
                      "every ray tests once (0: off)",
                      false},
                Field{"outlier_guard", &Params::outlier_guard, 0.0, 1.0,
                      "cover only the central 99% of the objects per axis when the full bounds are over 8x larger "
                      "(outliers go to the unbounded border cells; exact either way)",
                      false},
                Field{"thesis_reset", &Params::thesis_reset, 0.0, 1.0,
                      "avoid duplicate tests with the thesis' bool vector reset per ray (O(N) per ray) instead of "
                      "per-query stamps; for measuring the difference",
                      false}};
        }
    };

    /// Upper bound on the number of cells (the memory guard; the cell size grows to respect it).
    static constexpr std::size_t kMaxCells = std::size_t(1) << 22;

    UniformGrid() : UniformGrid(Params{}) {}
    explicit UniformGrid(const Params& p) : params_(p) {}

    void build(std::span<const Object> objects) override;
    void insert(const Object& object) override;
    void remove(Uid uid) override;
    void move(const Object& object) override;
    std::size_t size() const override { return slot_.size(); }
    std::size_t memory_bytes() const override;
    nlohmann::json stats() const override;
    void validate() const override;

    template <class Count, class Visit>
    void traverse(const Segment& s, Count& count, Visit&& visit);

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
    /// The large-object guard's test (see the top of this file).
    bool is_large(const grid::CellRange& r) const {
        return params_.max_cells > 0 && grid::cell_count(r) > std::size_t(params_.max_cells);
    }
    std::uint32_t next_stamp();

    Params params_;
    grid::Lattice lat_;
    bool clamped_ = false;          ///< the cell cap enlarged the cells
    bool trimmed_ = false;          ///< the outlier guard trimmed the lattice
    std::vector<BlockCell> cells_;  // cell → objects (copies of their boxes)
    BlockList large_;               // the large-object guard's objects (in no cell)
    std::vector<Entry> entries_;    // slot → object
    std::vector<std::uint32_t> free_slots_;
    std::unordered_map<Uid, std::uint32_t> slot_;  // uid → slot
    std::uint32_t stamp_ = 0;
    std::vector<std::uint32_t> stamps_;  // slot → id of the last query that reported it
    std::vector<std::uint8_t> tested_;   // thesis_reset mode only
};

template <class Count, class Visit>
void UniformGrid::traverse(const Segment& s, Count& count, Visit&& visit) {
    const SegmentSlabs slabs(s);
    const Vec3d p0 = s.p0.as<double>(), d = s.p1.as<double>() - p0;
    const grid::CellRange all{{0, 0, 0}, {lat_.res[0] - 1, lat_.res[1] - 1, lat_.res[2] - 1}};
    std::array<int, 3> start;
    for (int a = 0; a < 3; ++a) start[a] = lat_.index(a, p0[a]);
    const bool reset = params_.thesis_reset;
    if (reset) std::fill(tested_.begin(), tested_.end(), std::uint8_t(0));
    const std::uint32_t stamp = reset ? 0 : next_stamp();
    // Large objects first: each is in this list only, so it is tested once and needs no stamp.
    count.box_tests(large_.size());
    for (const BoxBlock& b : large_.cell().blocks) {
        float tn[BoxBlock::kLanes];
        for (unsigned hits = b.test(slabs, tn); hits; hits &= hits - 1) {
            const int lane = __builtin_ctz(hits);
            count.hits();
            if (!visit(entries_[b.slot[lane]].uid, tn[lane])) return;
        }
    }
    grid::walk(lat_, p0, d, all, start, 0.0, 1.0, [&](const std::array<int, 3>& c, double, double) {
        count.traversal();
        const BlockCell& cell = cells_[cell_id(c)];
        count.box_tests(cell.size);
        for (const BoxBlock& b : cell.blocks) {
            float tn[BoxBlock::kLanes];
            for (unsigned hits = b.test(slabs, tn); hits; hits &= hits - 1) {
                const int lane = __builtin_ctz(hits);
                const std::uint32_t slot = b.slot[lane];
                // An object in several cells is tested in each (cheaper than a branch per object
                // to skip it) and reported once.
                if (reset) {
                    if (tested_[slot]) continue;
                    tested_[slot] = 1;
                } else {
                    if (stamps_[slot] == stamp) continue;
                    stamps_[slot] = stamp;
                }
                count.hits();
                if (!visit(entries_[slot].uid, tn[lane])) return false;
            }
        }
        return true;
    });
}

}  // namespace rcb
