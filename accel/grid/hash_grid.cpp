#include "accel/grid/hash_grid.h"

#include <algorithm>
#include <bit>
#include <stdexcept>
#include <string>

#include "core/base/error.h"

namespace rcb {

// ---------------------------------------------------------------------------------------- CellTable

void CellTable::clear() {
    keys_.clear();
    keys_.shrink_to_fit();
    values_.clear();
    values_.shrink_to_fit();
    mask_ = 0;
    shift_ = 64;
    size_ = 0;
}

void CellTable::grow() {
    std::vector<std::uint64_t> old_keys = std::move(keys_);
    std::vector<std::uint32_t> old_values = std::move(values_);
    const std::size_t capacity = old_keys.empty() ? 16 : old_keys.size() * 2;
    keys_.assign(capacity, kEmpty);
    values_.assign(capacity, kNone);
    mask_ = capacity - 1;
    shift_ = 64 - std::countr_zero(capacity);
    size_ = 0;
    for (std::size_t i = 0; i < old_keys.size(); ++i)
        if (old_keys[i] != kEmpty) insert(old_keys[i], old_values[i]);
}

void CellTable::insert(std::uint64_t key, std::uint32_t value) {
    if (2 * (size_ + 1) > keys_.size()) grow();
    std::size_t i = home(key);
    while (keys_[i] != kEmpty && keys_[i] != key) i = (i + 1) & mask_;
    if (keys_[i] == kEmpty) ++size_;
    keys_[i] = key;
    values_[i] = value;
}

void CellTable::erase(std::uint64_t key) {
    if (keys_.empty()) return;
    std::size_t i = home(key);
    while (keys_[i] != key) {
        if (keys_[i] == kEmpty) return;
        i = (i + 1) & mask_;
    }
    // Backward-shift deletion: move later members of the probe run into the hole when their home
    // position does not lie cyclically in (hole, j].
    std::size_t hole = i;
    for (std::size_t j = (hole + 1) & mask_; keys_[j] != kEmpty; j = (j + 1) & mask_) {
        const std::size_t h = home(keys_[j]);
        const bool stays = hole <= j ? (hole < h && h <= j) : (hole < h || h <= j);
        if (stays) continue;
        keys_[hole] = keys_[j];
        values_[hole] = values_[j];
        hole = j;
    }
    keys_[hole] = kEmpty;
    values_[hole] = kNone;
    --size_;
}

// ----------------------------------------------------------------------------------------- HashGrid

HashGrid::HashGrid(const Params& p) : params_(p) {
    set_cast_threads(p.cast_threads);
    // The ranges in Params keep subdivision^max_depth ≤ 4^6 = 4096 < kMaxFineRes; checked again
    // here because a Params can be built in code without the registry's validation.
    double fine = 1;
    for (int i = 0; i < p.max_depth; ++i) fine *= p.subdivision;
    if (p.subdivision < 2 || p.max_depth < 0 || p.max_capacity < 1 || !(p.amp > 0) || fine > kMaxFineRes / 16)
        throw InputError("hg: subdivision^max_depth must be at most " + std::to_string(kMaxFineRes / 16) +
                         ", subdivision ≥ 2, max_capacity ≥ 1, amp > 0");
}

grid::CellRange HashGrid::range_at(const grid::CellRange& fine, int depth) const {
    const int div = pow_[params_.max_depth - depth];
    grid::CellRange r;
    for (int a = 0; a < 3; ++a) {
        r.lo[a] = fine.lo[a] / div;
        r.hi[a] = fine.hi[a] / div;
    }
    return r;
}

grid::CellRange HashGrid::children_of(const Index& i) const {
    const int f = params_.subdivision;
    grid::CellRange r;
    for (int a = 0; a < 3; ++a) {
        r.lo[a] = i[a] * f;
        r.hi[a] = i[a] * f + f - 1;
    }
    return r;
}

bool HashGrid::covers(const grid::CellRange& fine, int depth, const Index& i) const {
    const grid::CellRange r = range_at(fine, depth + 1), c = children_of(i);
    for (int a = 0; a < 3; ++a)
        if (r.lo[a] > c.lo[a] || r.hi[a] < c.hi[a]) return false;
    return true;
}

grid::CellRange HashGrid::child_range(const grid::CellRange& fine, int depth, const Index& i) const {
    grid::CellRange r = range_at(fine, depth + 1);
    const grid::CellRange c = children_of(i);
    for (int a = 0; a < 3; ++a) {
        r.lo[a] = std::clamp(r.lo[a], c.lo[a], c.hi[a]);
        r.hi[a] = std::clamp(r.hi[a], c.lo[a], c.hi[a]);
    }
    return r;
}

void HashGrid::build(std::span<const Object> objects) {
    const Aabb world = grid::lattice_bounds(objects, params_.outlier_guard, &trimmed_);
    would_trim_ = false;
    if (!params_.outlier_guard) grid::lattice_bounds(objects, true, &would_trim_);  // for stats() only
    const int f = params_.subdivision, depth = params_.max_depth;
    pow_.assign(depth + 1, 1);
    for (int k = 1; k <= depth; ++k) pow_[k] = pow_[k - 1] * f;
    const int max_top = kMaxFineRes / pow_[depth];
    // Eq. 4.2: cells_per_dimension = (number × amp)^(1/3), over the world's longest edge.
    const double per_dim = std::max(1.0, std::cbrt(double(objects.size()) * params_.amp));
    const double longest = double(world.longest_edge());
    double size = longest > 0 ? longest / per_dim : 1.0;
    std::array<int, 3> res = grid::resolution(world, size, max_top);
    clamped_ = false;
    // Memory guard: the finest lattice must fit the key; enlarge the top cells if it does not.
    for (int a = 0; a < 3; ++a)
        if (double(world.max[a]) - double(world.min[a]) > double(max_top) * size) clamped_ = true;
    if (clamped_) {
        size = double(longest) / double(max_top) * 1.0001;
        res = grid::resolution(world, size, max_top);
    }
    lat_.assign(depth + 1, grid::Lattice{});
    for (int k = 0; k <= depth; ++k) {
        lat_[k].origin = world.min.as<double>();
        lat_[k].size = size / pow_[k];
        lat_[k].inv_size = 1.0 / lat_[k].size;
        lat_[k].res = {res[0] * pow_[k], res[1] * pow_[k], res[2] * pow_[k]};
    }
    table_.clear();
    cells_.clear();
    cells_.shrink_to_fit();
    retry_at_.clear();
    retry_at_.shrink_to_fit();
    free_cells_.clear();
    entries_.clear();
    entries_.reserve(objects.size());
    free_slots_.clear();
    slot_.clear();
    slot_.reserve(objects.size());
    entries_total_ = 0;
    build_objects_ = objects.size();
    large_.clear();
    refused_splits_ = guard_collapses_ = unguarded_overruns_ = ceiling_refusals_ = 0;
    for (const Object& o : objects) insert(o);
}

std::uint32_t HashGrid::find_or_create(int depth, const Index& i) {
    const std::uint64_t key = key_of(depth, i);
    std::uint32_t id = table_.find(key);
    if (id != CellTable::kNone) return id;
    if (!free_cells_.empty()) {
        id = free_cells_.back();
        free_cells_.pop_back();
    } else {
        id = std::uint32_t(cells_.size());
        cells_.emplace_back();
        retry_at_.push_back(0);
    }
    Cell& c = cells_[id];
    c.key = key;
    c.count = 0;
    retry_at_[id] = 0;
    c.subdivided = false;
    c.own.clear();
    table_.insert(key, id);
    ++writes_;
    return id;
}

void HashGrid::delete_cell(std::uint32_t id) {
    Cell& c = cells_[id];
    entries_total_ -= c.own.size;
    table_.erase(c.key);
    c.key = CellTable::kEmpty;
    c.count = 0;
    c.subdivided = false;
    c.own = BlockCell{};
    free_cells_.push_back(id);
    ++writes_;
}

std::vector<std::uint32_t> HashGrid::take_own(std::uint32_t id) {
    BlockCell& own = cells_[id].own;
    std::vector<std::uint32_t> slots(own.size);
    for (std::uint32_t k = 0; k < own.size; ++k) slots[k] = own.slot(k);
    own.clear();
    return slots;
}

void HashGrid::set_own(std::uint32_t id, const std::vector<std::uint32_t>& slots) {
    cells_[id].own.clear();
    for (std::uint32_t slot : slots) own_push(id, slot);
}

void HashGrid::insert_into(int depth, const Index& i, std::uint32_t slot, const grid::CellRange& fine) {
    const std::uint32_t id = find_or_create(depth, i);
    ++cells_[id].count;
    if (cells_[id].subdivided) {
        if (covers(fine, depth, i)) {
            own_push(id, slot);
            ++entries_total_;
            return;
        }
        const grid::CellRange r = child_range(fine, depth, i);
        // The memory guard on the way down too: the splits were made for earlier objects, and an
        // object arriving later (inserted or moved, or at build after the first splits) would
        // otherwise be copied into every child it overlaps however crowded the cell is (identical
        // boxes: every insert lands in the same subdivided cells). Over the budget, the cell
        // collapses into a leaf holding each of its objects once, and the object joins it.
        // With the guard off, the ceiling (active_budget) collapses the cell instead.
        const std::size_t child_entries = grid::cell_count(r);
        unguarded_overruns_ += !params_.entries_guard && entries_total_ + child_entries > entry_budget();
        if (entries_total_ + child_entries > active_budget()) {
            collapse(id, depth, i);
            ++(params_.entries_guard ? guard_collapses_ : ceiling_refusals_);
            own_push(id, slot);
            ++entries_total_;
            retry_at_[id] = 2 * cells_[id].own.size;
            return;
        }
        grid::for_each_cell(r, [&](const Index& j) { insert_into(depth + 1, j, slot, fine); });
        return;
    }
    own_push(id, slot);
    ++entries_total_;
    if (depth < params_.max_depth && cells_[id].own.size > std::uint32_t(params_.max_capacity) &&
        cells_[id].own.size >= retry_at_[id])
        split(id, depth, i);
}

void HashGrid::split(std::uint32_t id, int depth, const Index& i) {
    std::vector<std::uint32_t> objects = take_own(id);
    std::vector<std::uint32_t> staying, moving;
    for (std::uint32_t slot : objects)
        (covers(lat_[params_.max_depth].range_of(entries_[slot].box), depth, i) ? staying : moving).push_back(slot);
    // Refused when every object covers the cell (splitting would only copy them) or when the
    // children's entries would exceed the memory budget.
    std::size_t child_entries = 0;
    for (std::uint32_t slot : moving) {
        const grid::CellRange r = child_range(lat_[params_.max_depth].range_of(entries_[slot].box), depth, i);
        child_entries += grid::cell_count(r);
    }
    // The split stops at 3/4 of the budget while a descending object collapses a cell only at the
    // full budget (insert_into): the gap keeps a collapsed cell from splitting straight back.
    // With the guard off, the ceiling (active_budget) refuses instead.
    const std::size_t after = entries_total_ - moving.size() + child_entries;
    const bool over_budget = after > active_budget() / 4 * 3;
    unguarded_overruns_ += !params_.entries_guard && after > entry_budget() / 4 * 3 && !moving.empty();
    if (moving.empty() || over_budget) {
        // Refused: try again once the leaf has doubled (amortised O(1) per insert, see the header).
        if (over_budget && !moving.empty()) ++(params_.entries_guard ? refused_splits_ : ceiling_refusals_);
        retry_at_[id] = std::uint32_t(2 * objects.size());
        set_own(id, objects);
        return;
    }
    entries_total_ -= moving.size();
    set_own(id, staying);
    cells_[id].subdivided = true;
    std::vector<std::uint32_t> children;
    for (std::uint32_t slot : moving) {
        const grid::CellRange fine = lat_[params_.max_depth].range_of(entries_[slot].box);
        const grid::CellRange r = child_range(fine, depth, i);
        grid::for_each_cell(r, [&](const Index& j) {
            const std::uint32_t c = find_or_create(depth + 1, j);
            if (cells_[c].count == 0) children.push_back(c);
            ++cells_[c].count;
            own_push(c, slot);
            ++entries_total_;
        });
    }
    if (depth + 1 >= params_.max_depth) return;
    for (std::uint32_t c : children) {
        if (cells_[c].own.size <= std::uint32_t(params_.max_capacity) || cells_[c].own.size < retry_at_[c]) continue;
        const std::uint64_t key = cells_[c].key;
        Index j{int((key >> 40) & 0xFFFFF), int((key >> 20) & 0xFFFFF), int(key & 0xFFFFF)};
        split(c, depth + 1, j);
    }
}

void HashGrid::gather_and_delete_children(int depth, const Index& i, std::vector<std::uint32_t>& out) {
    const grid::CellRange r = children_of(i);
    grid::for_each_cell(r, [&](const Index& j) {
        const std::uint32_t c = table_.find(key_of(depth + 1, j));
        if (c == CellTable::kNone) return;
        const BlockCell& own = cells_[c].own;
        for (std::uint32_t k = 0; k < own.size; ++k) out.push_back(own.slot(k));
        cells_[c].own.clear();  // moved to `out`, still counted in entries_total_
        if (cells_[c].subdivided) gather_and_delete_children(depth + 1, j, out);
        delete_cell(c);
    });
}

void HashGrid::collapse(std::uint32_t id, int depth, const Index& i) {
    std::vector<std::uint32_t> all = take_own(id);
    gather_and_delete_children(depth, i, all);
    const std::size_t gathered = all.size();
    std::sort(all.begin(), all.end());
    all.erase(std::unique(all.begin(), all.end()), all.end());
    entries_total_ -= gathered - all.size();
    set_own(id, all);
    cells_[id].subdivided = false;
    retry_at_[id] = 0;
}

void HashGrid::remove_from(int depth, const Index& i, std::uint32_t slot, const grid::CellRange& fine) {
    const std::uint32_t id = table_.find(key_of(depth, i));
    --cells_[id].count;
    auto erase_own = [&] {
        cells_[id].own.erase(slot);
        ++writes_;
        --entries_total_;
    };
    if (cells_[id].subdivided) {
        if (covers(fine, depth, i)) {
            erase_own();
        } else {
            const grid::CellRange r = child_range(fine, depth, i);
            grid::for_each_cell(r, [&](const Index& j) { remove_from(depth + 1, j, slot, fine); });
        }
        if (cells_[id].count == 0) {
            std::vector<std::uint32_t> rest;  // none left; defensive
            gather_and_delete_children(depth, i, rest);
            entries_total_ -= rest.size();
            delete_cell(id);
        } else if (cells_[id].count <= std::uint32_t(params_.max_capacity / 2)) {
            collapse(id, depth, i);
        }
        return;
    }
    erase_own();
    // A refused leaf that shrank tries again once it has doubled from its new size.
    retry_at_[id] = std::min(retry_at_[id], 2 * cells_[id].own.size);
    if (cells_[id].count == 0) delete_cell(id);
}

void HashGrid::rewrite_in(int depth, const Index& i, std::uint32_t slot, const grid::CellRange& fine, const Aabb& box) {
    const std::uint32_t id = table_.find(key_of(depth, i));
    if (!cells_[id].subdivided || covers(fine, depth, i)) {
        cells_[id].own.rewrite(slot, box);
        ++writes_;
        return;
    }
    const grid::CellRange r = child_range(fine, depth, i);
    grid::for_each_cell(r, [&](const Index& j) { rewrite_in(depth + 1, j, slot, fine, box); });
}

void HashGrid::insert(const Object& o) {
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
    const grid::CellRange fine = lat_[params_.max_depth].range_of(o.box);
    const grid::CellRange r = range_at(fine, 0);
    if (is_large(r)) {
        large_.insert(o.box, slot);
        return;
    }
    grid::for_each_cell(r, [&](const Index& i) { insert_into(0, i, slot, fine); });
}

void HashGrid::remove(Uid uid) {
    auto it = slot_.find(uid);
    const std::uint32_t slot = it->second;
    slot_.erase(it);
    if (large_.contains(slot)) {
        large_.erase(slot);
    } else {
        const grid::CellRange fine = lat_[params_.max_depth].range_of(entries_[slot].box);
        const grid::CellRange r = range_at(fine, 0);
        grid::for_each_cell(r, [&](const Index& i) { remove_from(0, i, slot, fine); });
    }
    entries_[slot].uid = 0;
    free_slots_.push_back(slot);
}

void HashGrid::move(const Object& o) {
    const std::uint32_t slot = slot_.at(o.uid);
    const grid::Lattice& fine_lat = lat_[params_.max_depth];
    if (fine_lat.range_of(entries_[slot].box) == fine_lat.range_of(o.box)) {
        // Same cells at every depth: only the box and its copies change.
        entries_[slot].box = o.box;
        if (large_.contains(slot)) {
            large_.rewrite(slot, o.box);
        } else {
            const grid::CellRange fine = fine_lat.range_of(o.box), r = range_at(fine, 0);
            grid::for_each_cell(r, [&](const Index& i) { rewrite_in(0, i, slot, fine, o.box); });
        }
        return;
    }
    remove(o.uid);
    insert(o);
}

std::size_t HashGrid::memory_bytes() const {
    std::size_t bytes = sizeof(*this) + table_.memory_bytes();
    bytes += cells_.capacity() * sizeof(Cell) + retry_at_.capacity() * sizeof(std::uint32_t);
    for (const Cell& c : cells_) bytes += c.own.blocks.capacity() * sizeof(BoxBlock);
    bytes += free_cells_.capacity() * sizeof(std::uint32_t);
    bytes += entries_.capacity() * sizeof(Entry) + free_slots_.capacity() * sizeof(std::uint32_t);
    bytes += slot_.bucket_count() * sizeof(void*) + slot_.size() * (sizeof(void*) + 2 * sizeof(std::uint32_t));
    bytes += lat_.capacity() * sizeof(grid::Lattice) + pow_.capacity() * sizeof(int) + large_.memory_bytes() +
             scratch_bytes();
    return bytes;
}

nlohmann::json HashGrid::stats() const {
    std::vector<std::size_t> per_depth(params_.max_depth + 1, 0);
    std::size_t entries = 0, subdivided = 0, largest = 0, over = 0;
    int deepest = 0;
    table_.for_each([&](std::uint64_t key, std::uint32_t id) {
        const int depth = int(key >> 60);
        ++per_depth[depth];
        deepest = std::max(deepest, depth);
        entries += cells_[id].own.size;
        largest = std::max(largest, std::size_t(cells_[id].own.size));
        subdivided += cells_[id].subdivided;
        over += !cells_[id].subdivided && depth < params_.max_depth &&
                cells_[id].own.size > std::uint32_t(params_.max_capacity);
    });
    nlohmann::json j = {{"cells", table_.size()},
                        {"cells_per_depth", per_depth},
                        {"max_depth_used", deepest},
                        {"subdivided_cells", subdivided},
                        {"entries", entries},
                        {"largest_cell", largest},
                        {"over_capacity_leaves", over},
                        {"top_res", {lat_[0].res[0], lat_[0].res[1], lat_[0].res[2]}},
                        {"top_cell_size", lat_[0].size},
                        {"top_res_clamped", clamped_},
                        {"outlier_trimmed", trimmed_},
                        {"refused_splits", refused_splits_},
                        {"guard_collapses", guard_collapses_},
                        {"large_objects", large_.size()}};
    // A guard switched off that would have fired: said here, since the grid is unbounded without it.
    nlohmann::json off = nlohmann::json::object();
    if (const std::size_t would_list = grid::unguarded_large_objects(
            params_.max_cells, slot_, entries_,
            [&](const Aabb& b) { return range_at(lat_[params_.max_depth].range_of(b), 0); }))
        off["max_cells"] = would_list;
    if (unguarded_overruns_) off["entries_guard"] = unguarded_overruns_;
    if (ceiling_refusals_) off["entries_ceiling"] = ceiling_refusals_;
    if (would_trim_) off["outlier_guard"] = true;
    if (!off.empty()) j["guards_off"] = off;
    return j;
}

void HashGrid::check() const {
    auto fail = [](const std::string& what) { broken_invariant("hg", what); };
    const std::vector<std::uint8_t> live = grid::live_slots(entries_, slot_, free_slots_, "hg");
    // Hash invariants: every key maps to a live cell carrying that key, and every live cell is keyed.
    std::size_t keyed = 0;
    table_.for_each([&](std::uint64_t key, std::uint32_t id) {
        if (id >= cells_.size() || cells_[id].key != key) fail("hash entry points at a cell with another key");
        if (table_.find(key) != id) fail("hash entry not reachable by its probe sequence");
        ++keyed;
    });
    if (keyed != table_.size() || keyed + free_cells_.size() != cells_.size()) fail("cells are neither keyed nor free");
    // Expected contents: replay every object's placement over the current subdivision.
    std::vector<std::vector<std::uint32_t>> expected(cells_.size());
    std::vector<std::uint32_t> expected_count(cells_.size(), 0);
    const int max_depth = params_.max_depth;
    grid::check_large_objects(large_, entries_, live, "hg");
    for (std::size_t slot = 0; slot < entries_.size(); ++slot) {
        if (!live[slot]) continue;
        const grid::CellRange fine = lat_[max_depth].range_of(entries_[slot].box);
        const bool large = is_large(range_at(fine, 0));
        if (large != large_.contains(std::uint32_t(slot)))
            fail("uid " + std::to_string(entries_[slot].uid) +
                 (large ? " is large but not in the large-object list" : " is in the large-object list but not large"));
        if (large) continue;
        auto place = [&](auto&& self, int depth, const Index& i) -> void {
            const std::uint32_t id = table_.find(key_of(depth, i));
            if (id == CellTable::kNone)
                fail("uid " + std::to_string(entries_[slot].uid) + " overlaps a missing cell at depth " +
                     std::to_string(depth));
            ++expected_count[id];
            if (!cells_[id].subdivided || covers(fine, depth, i)) {
                expected[id].push_back(std::uint32_t(slot));
                return;
            }
            const grid::CellRange r = child_range(fine, depth, i);
            grid::for_each_cell(r, [&](const Index& j) { self(self, depth + 1, j); });
        };
        const grid::CellRange r = range_at(fine, 0);
        grid::for_each_cell(r, [&](const Index& i) { place(place, 0, i); });
    }
    std::vector<std::uint32_t> have;
    std::size_t total = 0;
    table_.for_each([&](std::uint64_t key, std::uint32_t id) {
        const Cell& c = cells_[id];
        const int depth = int(key >> 60);
        const Index i{int((key >> 40) & 0xFFFFF), int((key >> 20) & 0xFFFFF), int(key & 0xFFFFF)};
        const std::string where = "cell (" + std::to_string(depth) + ": " + std::to_string(i[0]) + "," +
                                  std::to_string(i[1]) + "," + std::to_string(i[2]) + ")";
        if (depth > max_depth) fail(where + " is below max_depth");
        for (int a = 0; a < 3; ++a)
            if (i[a] >= lat_[depth].res[a]) fail(where + " lies outside the lattice");
        if (depth > 0) {
            Index p{i[0] / params_.subdivision, i[1] / params_.subdivision, i[2] / params_.subdivision};
            const std::uint32_t parent = table_.find(key_of(depth - 1, p));
            if (parent == CellTable::kNone || !cells_[parent].subdivided) fail(where + " has no subdivided parent");
        }
        if (c.count == 0) fail(where + " is empty but stored");
        if (c.count != expected_count[id])
            fail(where + " counts " + std::to_string(c.count) + " objects, " + std::to_string(expected_count[id]) +
                 " reach it");
        if (const std::string defect = c.own.defect(); !defect.empty()) fail(where + ": " + defect);
        have.clear();
        for (std::uint32_t k = 0; k < c.own.size; ++k) {
            have.push_back(c.own.slot(k));
            if (c.own.slot(k) < entries_.size() && !(c.own.box(k) == entries_[c.own.slot(k)].box))
                fail(where + " holds a stale box copy of uid " + std::to_string(entries_[c.own.slot(k)].uid));
        }
        std::sort(have.begin(), have.end());
        std::vector<std::uint32_t> want = expected[id];
        std::sort(want.begin(), want.end());
        if (have != want)
            fail(where + " holds " + std::to_string(have.size()) + " objects, expected " + std::to_string(want.size()) +
                 " (stale or missing entries)");
        if (c.subdivided) {
            if (depth >= max_depth) fail(where + " is subdivided at max_depth");
            if (c.count <= std::uint32_t(params_.max_capacity / 2))
                fail(where + " is subdivided but should have collapsed");
        }
        total += c.own.size;
    });
    if (total != entries_total_)
        fail("entry total is " + std::to_string(entries_total_) + ", cells hold " + std::to_string(total));
}

}  // namespace rcb
