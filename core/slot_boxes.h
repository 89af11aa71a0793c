#pragma once
/// Live objects in dense slots 0..n-1 with their boxes and a uid → slot index. A remove moves the
/// last slot into the hole, so the slots stay dense and a structure keeps whatever else it has per
/// object in plain arrays indexed by slot (Embree's primitive ids, Bullet's leaves) and the LBVH
/// builds from the arrays directly.

#include <cstdint>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/geometry.h"
#include "core/scene.h"

namespace rcb {

class SlotBoxes {
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
    /// element into the returned slot and pops them, as this does.
    std::uint32_t remove(Uid uid) {
        auto it = index_.find(uid);
        const std::uint32_t slot = it->second;
        index_.erase(it);
        const auto last = static_cast<std::uint32_t>(uids_.size() - 1);
        if (slot != last) {
            uids_[slot] = uids_[last];
            boxes_[slot] = boxes_[last];
            index_[uids_[slot]] = slot;
        }
        uids_.pop_back();
        boxes_.pop_back();
        return slot;
    }

    /// Gives the live object `o.uid` the box `o.box`; returns its slot.
    std::uint32_t move(const Object& o) {
        const std::uint32_t slot = index_.at(o.uid);
        boxes_[slot] = o.box;
        return slot;
    }

    std::size_t size() const { return uids_.size(); }
    bool empty() const { return uids_.empty(); }
    Uid uid(std::uint32_t slot) const { return uids_[slot]; }
    const Aabb& box(std::uint32_t slot) const { return boxes_[slot]; }
    const std::vector<Uid>& uids() const { return uids_; }
    const std::vector<Aabb>& boxes() const { return boxes_; }
    /// The slot of `uid`, or nullptr when it is not live.
    const std::uint32_t* find(Uid uid) const {
        auto it = index_.find(uid);
        return it == index_.end() ? nullptr : &it->second;
    }

    /// The arrays' capacity and the hash index (buckets and one node per entry).
    std::size_t memory_bytes() const {
        return uids_.capacity() * sizeof(Uid) + boxes_.capacity() * sizeof(Aabb) +
               index_.bucket_count() * sizeof(void*) + index_.size() * (sizeof(void*) + 2 * sizeof(std::uint32_t));
    }

    /// Throws std::logic_error "<who>: ..." unless the arrays agree in size, every slot's uid maps back
    /// to that slot, and every box has min <= max.
    void validate(const std::string& who) const {
        const std::size_t n = uids_.size();
        if (boxes_.size() != n || index_.size() != n)
            throw std::logic_error(who + ": uid index has " + std::to_string(index_.size()) + " entries and " +
                                   std::to_string(boxes_.size()) + " boxes for " + std::to_string(n) + " slots");
        for (std::size_t i = 0; i < n; ++i) {
            auto it = index_.find(uids_[i]);
            if (it == index_.end() || it->second != i)
                throw std::logic_error(who + ": uid index does not point at slot " + std::to_string(i));
            const Aabb& b = boxes_[i];
            if (!(b.min.x <= b.max.x && b.min.y <= b.max.y && b.min.z <= b.max.z))
                throw std::logic_error(who + ": uid " + std::to_string(uids_[i]) + " has min > max");
        }
    }

private:
    std::vector<Uid> uids_;
    std::vector<Aabb> boxes_;
    std::unordered_map<Uid, std::uint32_t> index_;
};

}  // namespace rcb
