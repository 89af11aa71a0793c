#pragma once
/// What the uniform grid (thesis §4.2) and the hierarchical hash grid (§4.3) share: a lattice of
/// cells with unbounded border cells, the 3D-DDA cell walk of Amanatides & Woo (1987, "A fast voxel
/// traversal algorithm for ray tracing") restricted to a segment (thesis Algorithm 1), the loop over
/// a range of cells, the lattice's bounds with the outlier guard, and the checks of an object table
/// that check() uses.

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <string_view>
#include <unordered_map>
#include <utility>
#include <vector>

#include "core/base/geometry.h"
#include "core/scene/scene.h"
#include "accel/interface/structure.h"
#include "accel/common/box_block.h"

namespace rcb {

namespace grid {

/// A cell's index per axis.
using Index = std::array<int, 3>;

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
    /// Every cell of the lattice.
    CellRange cells() const { return {{0, 0, 0}, {res[0] - 1, res[1] - 1, res[2] - 1}}; }
    /// Position of the plane between cells k − 1 and k on `axis`.
    double plane(int axis, int k) const { return origin[axis] + double(k) * size; }
};

/// The 3D-DDA of Amanatides & Woo over `lat`, restricted to the cells of `range` and the segment
/// parameters [t0, t1], starting in cell `cur` (inside `range`). Calls
/// `cell(idx, t_in, t_out) -> bool` for every cell the segment crosses, in order; returns false as
/// soon as `cell` does. Plane crossings are computed afresh from the plane's index in double
/// precision (no accumulated t increments), and there is no plane beyond the lattice's border
/// (border cells are unbounded). Zero direction components never step. Each cell's way out (the
/// axis and side of the plane crossed, or the segment's end) goes to `count.branch`: a ray in its
/// own direction takes them in an order the branch predictor has not seen (counters.h).
template <class Count, class Cell>
bool walk(const Lattice& lat, const Vec3d& p0, const Vec3d& d, const CellRange& range, std::array<int, 3> cur,
          double t0, double t1, Count& count, Cell&& cell) {
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
        if (!(t_cross <= t1)) {  // the segment ends in this cell
            count.branch(7);
            return true;
        }
        count.branch(std::uint32_t(1 + a + 3 * (step[a] > 0)));
        cur[a] += step[a];
        if (cur[a] < range.lo[a] || cur[a] > range.hi[a]) return true;
        t_in = std::max(t_in, t_cross);
        next[a] = crossing(a);
    }
}

/// The live slots of a grid's object table (entries with a `uid`, a uid → slot index, a free list);
/// broken_invariant(who, …) unless the three agree.
template <class Entry>
std::vector<std::uint8_t> live_slots(const std::vector<Entry>& entries,
                                     const std::unordered_map<Uid, std::uint32_t>& index,
                                     const std::vector<std::uint32_t>& free_slots, std::string_view who) {
    auto fail = [who](const std::string& what) { broken_invariant(who, what); };
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

/// The large-object list holds only live slots, each with its current box; broken_invariant(who, …)
/// otherwise.
template <class Entry>
void check_large_objects(const BlockList& large, const std::vector<Entry>& entries,
                         const std::vector<std::uint8_t>& live, std::string_view who) {
    auto fail = [who](const std::string& what) { broken_invariant(who, what); };
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

/// Calls `f(cell)` for every cell of the range `r`, x fastest (the order of a grid's cell array).
template <class F>
void for_each_cell(const CellRange& r, F&& f) {
    Index i;
    for (i[2] = r.lo[2]; i[2] <= r.hi[2]; ++i[2])
        for (i[1] = r.lo[1]; i[1] <= r.hi[1]; ++i[1])
            for (i[0] = r.lo[0]; i[0] <= r.hi[0]; ++i[0]) f(std::as_const(i));
}

/// A closest-hit walk (hit_policy.h) stops at the first cell entered after this, given the best
/// hit's t: a cell entered within float rounding of it may still hold a tie with a smaller uid.
inline double closest_cutoff(float best_t) { return double(best_t) + 1e-6 * (1.0 + std::abs(double(best_t))); }

/// The grids' default for the large-object guard (UniformGrid::Params::max_cells, HashGrid's too):
/// a 3×3×3 block.
inline constexpr int kDefaultMaxCells = 27;

/// For a grid's stats "guards_off": with the large-object guard switched off (`max_cells` 0), how
/// many of the objects (`slot`: uid → index into `entries`) it would have listed at its default;
/// 0 when the guard is on. `range_of(box)` is the cell range the guard tests.
template <class Entries, class RangeOf>
std::size_t unguarded_large_objects(int max_cells, const std::unordered_map<Uid, std::uint32_t>& slot,
                                    const Entries& entries, RangeOf&& range_of) {
    if (max_cells != 0) return 0;
    std::size_t n = 0;
    for (const auto& [uid, s] : slot) n += cell_count(range_of(entries[s].box)) > std::size_t(kDefaultMaxCells);
    return n;
}

}  // namespace grid

}  // namespace rcb
