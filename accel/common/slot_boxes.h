#pragma once
/// Live objects in dense slots 0..n-1 with their boxes and a uid → slot index. A remove moves the
/// last slot into the hole, so the slots stay dense and a structure keeps whatever else it has per
/// object in plain arrays indexed by slot (Embree's primitive ids, Bullet's leaves), the LBVH builds
/// from the arrays directly and brute force scans them.
///
/// The boxes come in two layouts: one Aabb per slot (SlotBoxes), or six float arrays of minima and
/// maxima per axis (SoaSlotBoxes) for a scan that vectorises over slots.

#include <array>
#include <cstdint>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/base/geometry.h"
#include "core/scene/scene.h"
#include "accel/interface/structure.h"

namespace rcb {

/// One Aabb per slot.
class AosBoxes {
public:
    void clear() { boxes_.clear(); }
    void reserve(std::size_t n) { boxes_.reserve(n); }
    void push_back(const Aabb& b) { boxes_.push_back(b); }
    void set(std::uint32_t slot, const Aabb& b) { boxes_[slot] = b; }
    /// Moves the last slot's box into `slot` and drops the last slot.
    void move_last_to(std::uint32_t slot) {
        boxes_[slot] = boxes_.back();
        boxes_.pop_back();
    }
    const Aabb& get(std::uint32_t slot) const { return boxes_[slot]; }
    std::size_t size() const { return boxes_.size(); }
    std::size_t memory_bytes() const { return boxes_.capacity() * sizeof(Aabb); }
    const std::vector<Aabb>& all() const { return boxes_; }

private:
    std::vector<Aabb> boxes_;
};

/// Per axis, one array of box minima and one of maxima.
class SoaBoxes {
public:
    void clear() {
        for (int a = 0; a < 3; ++a) min_[a].clear(), max_[a].clear();
    }
    void reserve(std::size_t n) {
        for (int a = 0; a < 3; ++a) min_[a].reserve(n), max_[a].reserve(n);
    }
    void push_back(const Aabb& b) {
        for (int a = 0; a < 3; ++a) min_[a].push_back(b.min[a]), max_[a].push_back(b.max[a]);
    }
    void set(std::uint32_t slot, const Aabb& b) {
        for (int a = 0; a < 3; ++a) min_[a][slot] = b.min[a], max_[a][slot] = b.max[a];
    }
    void move_last_to(std::uint32_t slot) {
        for (int a = 0; a < 3; ++a) {
            min_[a][slot] = min_[a].back(), max_[a][slot] = max_[a].back();
            min_[a].pop_back(), max_[a].pop_back();
        }
    }
    Aabb get(std::uint32_t slot) const {
        Aabb b;
        for (int a = 0; a < 3; ++a) b.min[a] = min_[a][slot], b.max[a] = max_[a][slot];
        return b;
    }
    std::size_t size() const { return min_[0].size(); }
    std::size_t memory_bytes() const {
        std::size_t bytes = 0;
        for (int a = 0; a < 3; ++a) bytes += (min_[a].capacity() + max_[a].capacity()) * sizeof(float);
        return bytes;
    }
    const float* min(int axis) const { return min_[axis].data(); }
    const float* max(int axis) const { return max_[axis].data(); }

private:
    std::array<std::vector<float>, 3> min_, max_;
};

template <class Boxes>
class SlotTable {
public:
    void clear() {
        uids_.clear();
        boxes_.clear();
        index_.clear();
    }
    void reserve(std::size_t n) {
        uids_.reserve(n);
        boxes_.reserve(n);
        index_.reserve(n);
    }

    /// Appends `o` (its uid not yet present); returns its slot.
    std::uint32_t insert(const Object& o) {
        const auto slot = static_cast<std::uint32_t>(uids_.size());
        index_.emplace(o.uid, slot);
        uids_.push_back(o.uid);
        boxes_.push_back(o.box);
        return slot;
    }

    /// Removes `uid` (present) and returns the slot it had. When that was not the last slot, the last
    /// slot's object now lives there: a caller with per-slot arrays of its own moves their last
    /// element into the returned slot and pops them, as this does. `old`, when given, receives the
    /// removed box.
    std::uint32_t remove(Uid uid, Aabb* old = nullptr) {
        auto it = index_.find(uid);
        const std::uint32_t slot = it->second;
        if (old) *old = boxes_.get(slot);
        index_.erase(it);
        const auto last = static_cast<std::uint32_t>(uids_.size() - 1);
        if (slot != last) {
            uids_[slot] = uids_[last];
            index_[uids_[slot]] = slot;
        }
        uids_.pop_back();
        boxes_.move_last_to(slot);
        return slot;
    }

    /// Gives the live object `o.uid` the box `o.box`; returns its slot. `old`, when given, receives
    /// the box it had.
    std::uint32_t move(const Object& o, Aabb* old = nullptr) {
        const std::uint32_t slot = index_.at(o.uid);
        if (old) *old = boxes_.get(slot);
        boxes_.set(slot, o.box);
        return slot;
    }

    std::size_t size() const { return uids_.size(); }
    bool empty() const { return uids_.empty(); }
    Uid uid(std::uint32_t slot) const { return uids_[slot]; }
    decltype(auto) box(std::uint32_t slot) const { return boxes_.get(slot); }
    const std::vector<Uid>& uids() const { return uids_; }
    const Boxes& layout() const { return boxes_; }
    /// The slot of `uid`, or nullptr when it is not live.
    const std::uint32_t* find(Uid uid) const {
        auto it = index_.find(uid);
        return it == index_.end() ? nullptr : &it->second;
    }

    /// The arrays' capacity and the hash index (buckets and one node per entry).
    std::size_t memory_bytes() const {
        return uids_.capacity() * sizeof(Uid) + boxes_.memory_bytes() + index_.bucket_count() * sizeof(void*) +
               index_.size() * (sizeof(void*) + 2 * sizeof(std::uint32_t));
    }

    /// broken_invariant(who, …) unless the arrays agree in size, every slot's uid maps back to that
    /// slot, and every box has min <= max.
    void check(std::string_view who) const {
        const std::size_t n = uids_.size();
        if (boxes_.size() != n || index_.size() != n)
            broken_invariant(who, "uid index has " + std::to_string(index_.size()) + " entries and " +
                                      std::to_string(boxes_.size()) + " boxes for " + std::to_string(n) + " slots");
        for (std::uint32_t i = 0; i < n; ++i) {
            auto it = index_.find(uids_[i]);
            if (it == index_.end() || it->second != i)
                broken_invariant(who, "uid index does not point at slot " + std::to_string(i));
            const Aabb b = boxes_.get(i);
            if (!(b.min.x <= b.max.x && b.min.y <= b.max.y && b.min.z <= b.max.z))
                broken_invariant(who, "uid " + std::to_string(uids_[i]) + " has min > max");
        }
    }

private:
    std::vector<Uid> uids_;
    Boxes boxes_;
    std::unordered_map<Uid, std::uint32_t> index_;
};

/// The peers' and the LBVH's table: one Aabb per slot.
using SlotBoxes = SlotTable<AosBoxes>;
/// Brute force's table: the boxes per axis, scanned in blocks.
using SoaSlotBoxes = SlotTable<SoaBoxes>;

}  // namespace rcb
