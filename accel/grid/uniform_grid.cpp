#include "accel/grid/uniform_grid.h"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace rcb {

void UniformGrid::build(std::span<const Object> objects) {
    const Aabb world = grid::lattice_bounds(objects, params_.outlier_guard, &trimmed_);
    would_trim_ = false;
    if (!params_.outlier_guard) grid::lattice_bounds(objects, true, &would_trim_);  // for stats() only
    const double longest = double(world.longest_edge());
    // Eq. 4.1: cells_per_dimension = (number / density)^(1/3), size = longest_edge / cells_per_dimension.
    const double per_dim = std::max(1.0, std::cbrt(double(objects.size()) / params_.density));
    double size = longest > 0 ? longest / per_dim : 1.0;
    clamped_ = false;
    std::array<int, 3> res = grid::resolution(world, size, int(kMaxCells));
    // Memory guard: enlarge the cells until the count fits the cap.
    while (double(res[0]) * res[1] * res[2] > double(kMaxCells)) {
        size *= 1.25;
        res = grid::resolution(world, size, int(kMaxCells));
        clamped_ = true;
    }
    lat_.origin = world.min.as<double>();
    lat_.size = size;
    lat_.inv_size = 1.0 / size;
    lat_.res = res;

    cells_.clear();
    cells_.shrink_to_fit();
    cells_.resize(std::size_t(res[0]) * res[1] * res[2]);
    entries_.clear();
    entries_.reserve(objects.size());
    free_slots_.clear();
    slot_.clear();
    slot_.reserve(objects.size());
    large_.clear();
    for (const Object& o : objects) insert(o);
}

void UniformGrid::add_to_cells(std::uint32_t slot, const grid::CellRange& r) {
    grid::for_each_cell(r, [&](const grid::Index& i) { cells_[cell_id(i)].push(entries_[slot].box, slot); });
    writes_ += grid::cell_count(r);
}

void UniformGrid::rewrite_box(std::uint32_t slot, const grid::CellRange& r, const Aabb& box) {
    grid::for_each_cell(r, [&](const grid::Index& i) { cells_[cell_id(i)].rewrite(slot, box); });
    writes_ += grid::cell_count(r);
}

void UniformGrid::remove_from_cells(std::uint32_t slot, const grid::CellRange& r) {
    grid::for_each_cell(r, [&](const grid::Index& i) { cells_[cell_id(i)].erase(slot); });
    writes_ += grid::cell_count(r);
}

void UniformGrid::insert(const Object& o) {
    std::uint32_t slot;
    if (!free_slots_.empty()) {
        slot = free_slots_.back();
        free_slots_.pop_back();
        entries_[slot] = Entry{o.box, o.uid};
    } else {
        slot = std::uint32_t(entries_.size());
        entries_.push_back(Entry{o.box, o.uid});
    }
    slot_.emplace(o.uid, slot);
    const grid::CellRange r = lat_.range_of(o.box);
    if (is_large(r))
        large_.insert(o.box, slot);
    else
        add_to_cells(slot, r);
}

void UniformGrid::remove(Uid uid) {
    auto it = slot_.find(uid);
    const std::uint32_t slot = it->second;
    slot_.erase(it);
    if (large_.contains(slot))
        large_.erase(slot);
    else
        remove_from_cells(slot, lat_.range_of(entries_[slot].box));
    entries_[slot].uid = 0;
    free_slots_.push_back(slot);
}

void UniformGrid::move(const Object& o) {
    const std::uint32_t slot = slot_.at(o.uid);
    Entry& e = entries_[slot];
    const grid::CellRange before = lat_.range_of(e.box), after = lat_.range_of(o.box);
    e.box = o.box;
    const bool was_large = large_.contains(slot), now_large = is_large(after);
    if (was_large || now_large) {
        if (was_large && now_large) {
            large_.rewrite(slot, o.box);
            return;
        }
        if (was_large)
            large_.erase(slot);
        else
            remove_from_cells(slot, before);
        if (now_large)
            large_.insert(o.box, slot);
        else
            add_to_cells(slot, after);
    } else if (!(before == after)) {
        remove_from_cells(slot, before);
        add_to_cells(slot, after);
    } else {
        rewrite_box(slot, after, o.box);
    }
}

std::size_t UniformGrid::memory_bytes() const {
    std::size_t bytes = sizeof(*this);
    bytes += cells_.capacity() * sizeof(BlockCell);
    for (const auto& c : cells_) bytes += c.blocks.capacity() * sizeof(BoxBlock);
    bytes += scratch_bytes();
    bytes += entries_.capacity() * sizeof(Entry) + free_slots_.capacity() * sizeof(std::uint32_t);
    bytes += slot_.bucket_count() * sizeof(void*) + slot_.size() * (sizeof(void*) + 2 * sizeof(std::uint32_t));
    bytes += large_.memory_bytes();
    return bytes;
}

nlohmann::json UniformGrid::stats() const {
    std::size_t entries = 0, non_empty = 0, largest = 0;
    for (const auto& c : cells_) {
        entries += c.size;
        non_empty += c.size != 0;
        largest = std::max(largest, std::size_t(c.size));
    }
    nlohmann::json j = {{"cells", cells_.size()},
                        {"res", {lat_.res[0], lat_.res[1], lat_.res[2]}},
                        {"cell_size", lat_.size},
                        {"non_empty_cells", non_empty},
                        {"entries", entries},
                        {"largest_cell", largest},
                        {"cell_cap_hit", clamped_},
                        {"outlier_trimmed", trimmed_},
                        {"large_objects", large_.size()}};
    // A guard switched off that would have fired: said here, since the grid is unbounded without it.
    nlohmann::json off = nlohmann::json::object();
    if (const std::size_t would_list = grid::unguarded_large_objects(params_.max_cells, slot_, entries_,
                                                                     [&](const Aabb& b) { return lat_.range_of(b); }))
        off["max_cells"] = would_list;
    if (would_trim_) off["outlier_guard"] = true;
    if (!off.empty()) j["guards_off"] = off;
    return j;
}

void UniformGrid::check() const {
    auto fail = [](const std::string& what) { broken_invariant("ug", what); };
    if (cells_.size() != std::size_t(lat_.res[0]) * lat_.res[1] * lat_.res[2])
        fail("cell array size differs from the resolution");
    if (cells_.size() > kMaxCells) fail("more cells than the cap");
    const std::vector<std::uint8_t> live = grid::live_slots(entries_, slot_, free_slots_, "ug");
    std::vector<std::size_t> seen(entries_.size(), 0);
    std::vector<std::uint32_t> sorted;
    grid::for_each_cell(lat_.cells(), [&](const grid::Index& i) {
        const auto& c = cells_[cell_id(i)];
        sorted.clear();
        for (std::uint32_t k = 0; k < c.size; ++k) sorted.push_back(c.slot(k));
        std::sort(sorted.begin(), sorted.end());
        if (std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end())
            fail("an object appears twice in one cell");
        if (const std::string defect = c.defect(); !defect.empty()) fail(defect);
        for (std::uint32_t k = 0; k < c.size; ++k) {
            const std::uint32_t slot = c.slot(k);
            if (slot >= entries_.size() || !live[slot])
                fail("stale entry (slot " + std::to_string(slot) + ") in a cell");
            if (!(c.box(k) == entries_[slot].box))
                fail("uid " + std::to_string(entries_[slot].uid) + " has a stale box copy in a cell");
            const grid::CellRange r = lat_.range_of(entries_[slot].box);
            for (int a = 0; a < 3; ++a)
                if (i[a] < r.lo[a] || i[a] > r.hi[a])
                    fail("uid " + std::to_string(entries_[slot].uid) + " stored in a cell it does not overlap");
            ++seen[slot];
        }
    });
    grid::check_large_objects(large_, entries_, live, "ug");
    for (std::size_t slot = 0; slot < entries_.size(); ++slot) {
        if (!live[slot]) continue;
        const Entry& e = entries_[slot];
        if (!(e.box.min.x <= e.box.max.x && e.box.min.y <= e.box.max.y && e.box.min.z <= e.box.max.z))
            fail("box with min > max");
        const grid::CellRange r = lat_.range_of(e.box);
        if (is_large(r) != large_.contains(std::uint32_t(slot)))
            fail("uid " + std::to_string(e.uid) +
                 (is_large(r) ? " is large but not in the large-object list"
                              : " is in the large-object list but not large"));
        const std::size_t expected = is_large(r) ? 0 : grid::cell_count(r);
        if (seen[slot] != expected)
            fail("uid " + std::to_string(e.uid) + " is in " + std::to_string(seen[slot]) + " cells, overlaps " +
                 std::to_string(expected));
    }
}

}  // namespace rcb
