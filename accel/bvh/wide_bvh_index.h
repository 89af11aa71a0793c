#pragma once
/// The wide BVH's index from uid to slot (block · 8 + lane; wide_bvh.h): a flat array indexed by
/// uid while the uids are dense (a recording's uids are 0..n−1 plus the inserts' new ones), and a
/// hash map for uids beyond it. A physics frame moves nearly every object, each move one lookup:
/// in uid order the flat array is read sequentially (one cache line per 16 uids), where a hash map
/// costs a hash and a pointer chase into a node per move. The array covers at most 4 entries per
/// object plus a fixed floor, so sparse uids (hostile scenes, uids near 2^32) fall back to the map
/// and memory stays bounded.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <unordered_map>
#include <vector>

#include "core/scene/scene.h"

namespace rcb {

class WideBvhIndex {
public:
    static constexpr std::uint32_t kAbsent = 0xffffffffu;

    std::size_t size() const { return count_; }
    bool empty() const { return count_ == 0; }

    /// The slot of `uid`, or kAbsent.
    std::uint32_t find(Uid uid) const {
        if (uid < flat_.size()) return flat_[uid];
        if (sparse_.empty()) return kAbsent;
        const auto it = sparse_.find(uid);
        return it == sparse_.end() ? kAbsent : it->second;
    }
    bool contains(Uid uid) const { return find(uid) != kAbsent; }

    /// Sets the slot of `uid`, present or not.
    void set(Uid uid, std::uint32_t slot) {
        if (uid < flat_.size() || grow_to_cover(uid)) {
            count_ += flat_[uid] == kAbsent;
            flat_[uid] = slot;
            return;
        }
        const auto [it, added] = sparse_.try_emplace(uid, slot);
        if (added)
            ++count_;
        else
            it->second = slot;
    }
    /// Drops `uid` (present).
    void erase(Uid uid) {
        if (uid < flat_.size()) {
            count_ -= flat_[uid] != kAbsent;
            flat_[uid] = kAbsent;
        } else {
            count_ -= sparse_.erase(uid);
        }
    }
    /// Empties the index, keeping the flat array's memory.
    void clear() {
        std::fill(flat_.begin(), flat_.end(), kAbsent);
        sparse_.clear();
        count_ = hint_ = 0;
    }
    /// Frees everything.
    void release() {
        std::vector<std::uint32_t>().swap(flat_);
        std::unordered_map<Uid, std::uint32_t>().swap(sparse_);
        count_ = hint_ = 0;
    }
    /// Before `objects` uids up to `max_uid` are set: the flat array covers them at once when
    /// they are dense enough, so that a build's uids (set in spatial order, not uid order) do not
    /// spill into the map while the count is still small.
    void reserve(std::size_t objects, Uid max_uid) {
        hint_ = std::max(hint_, objects);
        if (max_uid >= flat_.size() && std::size_t(max_uid) < limit()) grow(std::size_t(max_uid) + 1);
    }
    /// Before the uids of `other` are set (a progressive rebuild's next tree): as reserve().
    void reserve_like(const WideBvhIndex& other) {
        hint_ = std::max(hint_, other.count_);
        if (other.flat_.size() > flat_.size()) grow(other.flat_.size());
    }
    /// Drops up to `n` entries of the map (a replaced tree's index, freed a budget at a time);
    /// returns how many it dropped.
    std::size_t drop_some(std::size_t n) {
        std::size_t dropped = 0;
        for (; dropped < n && !sparse_.empty(); ++dropped) sparse_.erase(sparse_.begin());
        count_ -= dropped;
        return dropped;
    }
    /// Whether the map is empty (what drop_some() works on).
    bool map_empty() const { return sparse_.empty(); }

    /// Calls f(uid, slot) for every uid.
    template <class F>
    void for_each(F&& f) const {
        for (std::size_t u = 0; u < flat_.size(); ++u)
            if (flat_[u] != kAbsent) f(Uid(u), flat_[u]);
        for (const auto& [uid, slot] : sparse_) f(uid, slot);
    }

    std::size_t memory_bytes() const {
        return flat_.capacity() * sizeof(std::uint32_t) + sparse_.bucket_count() * sizeof(void*) +
               sparse_.size() * (sizeof(void*) + 2 * sizeof(std::uint32_t));
    }

private:
    /// The flat array's largest size: 4 entries per object (the count or the reserved count,
    /// whichever is larger) plus a floor of 4096.
    std::size_t limit() const { return 4 * std::max(count_ + 1, hint_) + 4096; }
    /// Grows the flat array to cover `uid` when that stays within limit().
    bool grow_to_cover(Uid uid) {
        const std::size_t cap = limit();
        if (std::size_t(uid) >= cap) return false;
        grow(std::min(cap, std::max(std::size_t(uid) + 1, 2 * flat_.size())));
        return true;
    }
    /// Resizes the flat array to `n` entries and moves the map's uids below n into it.
    void grow(std::size_t n) {
        flat_.resize(n, kAbsent);
        for (auto it = sparse_.begin(); it != sparse_.end();) {
            if (it->first < n) {
                flat_[it->first] = it->second;
                it = sparse_.erase(it);
            } else {
                ++it;
            }
        }
    }

    std::vector<std::uint32_t> flat_;                // slot per uid below its size (kAbsent: none)
    std::unordered_map<Uid, std::uint32_t> sparse_;  // the uids at or beyond flat_.size()
    std::size_t count_ = 0;
    std::size_t hint_ = 0;  // the object count reserve() announced
};

}  // namespace rcb
