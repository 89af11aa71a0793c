#include "core/structures/brute_force.h"

#include <stdexcept>
#include <string>

namespace rcb {

void BruteForce::build(std::span<const Object> objects) {
    for (int a = 0; a < 3; ++a) {
        min_[a].clear();
        max_[a].clear();
        min_[a].reserve(objects.size());
        max_[a].reserve(objects.size());
    }
    uids_.clear();
    uids_.reserve(objects.size());
    slot_.clear();
    slot_.reserve(objects.size());
    for (const Object& o : objects) insert(o);
}

void BruteForce::insert(const Object& o) {
    slot_.emplace(o.uid, static_cast<std::uint32_t>(uids_.size()));
    uids_.push_back(o.uid);
    for (int a = 0; a < 3; ++a) {
        min_[a].push_back(o.box.min[a]);
        max_[a].push_back(o.box.max[a]);
    }
}

void BruteForce::remove(Uid uid) {
    auto it = slot_.find(uid);
    const std::uint32_t slot = it->second;
    slot_.erase(it);
    const std::uint32_t last = static_cast<std::uint32_t>(uids_.size() - 1);
    if (slot != last) {
        uids_[slot] = uids_[last];
        slot_[uids_[slot]] = slot;
        for (int a = 0; a < 3; ++a) {
            min_[a][slot] = min_[a][last];
            max_[a][slot] = max_[a][last];
        }
    }
    uids_.pop_back();
    for (int a = 0; a < 3; ++a) {
        min_[a].pop_back();
        max_[a].pop_back();
    }
}

void BruteForce::move(const Object& o) {
    const std::uint32_t slot = slot_.at(o.uid);
    for (int a = 0; a < 3; ++a) {
        min_[a][slot] = o.box.min[a];
        max_[a][slot] = o.box.max[a];
    }
}

namespace {

/// The slab test of SegmentSlabs::clip over arrays of near and far planes, unrolled over the axes
/// so that it vectorises (a free function with restrict pointers: GCC 12 does not vectorise it as
/// a member). The operand order of each min/max keeps the NaN-dropping semantics of geometry.h.
void slab_test_boxes(const float* __restrict nx, const float* __restrict ny, const float* __restrict nz,
                     const float* __restrict fx, const float* __restrict fy, const float* __restrict fz, float ox,
                     float oy, float oz, float ix, float iy, float iz, std::size_t n, std::uint8_t* __restrict hit,
                     float* __restrict t_near) {
    for (std::size_t i = 0; i < n; ++i) {
        float tn = 0.0f, tf = 1.0f;
        float lo = (nx[i] - ox) * ix, hi = (fx[i] - ox) * ix;
        tn = lo > tn ? lo : tn;
        tf = hi < tf ? hi : tf;
        lo = (ny[i] - oy) * iy, hi = (fy[i] - oy) * iy;
        tn = lo > tn ? lo : tn;
        tf = hi < tf ? hi : tf;
        lo = (nz[i] - oz) * iz, hi = (fz[i] - oz) * iz;
        tn = lo > tn ? lo : tn;
        tf = hi < tf ? hi : tf;
        hit[i] = tn <= tf;
        t_near[i] = tn;
    }
}

}  // namespace

void BruteForce::test_block(const SegmentSlabs& slabs, std::size_t begin, std::size_t end) {
    const float* near[3];
    const float* far[3];
    for (int a = 0; a < 3; ++a) {
        near[a] = (slabs.near_is_max[a] ? max_[a].data() : min_[a].data()) + begin;
        far[a] = (slabs.near_is_max[a] ? min_[a].data() : max_[a].data()) + begin;
    }
    slab_test_boxes(near[0], near[1], near[2], far[0], far[1], far[2], slabs.origin.x, slabs.origin.y, slabs.origin.z,
                    slabs.inv.x, slabs.inv.y, slabs.inv.z, end - begin, hit_.data(), t_near_.data());
}

std::size_t BruteForce::memory_bytes() const {
    std::size_t bytes = uids_.capacity() * sizeof(Uid);
    for (int a = 0; a < 3; ++a) bytes += (min_[a].capacity() + max_[a].capacity()) * sizeof(float);
    // unordered_map: one bucket pointer per bucket, one heap node (next, key, value) per entry.
    bytes += slot_.bucket_count() * sizeof(void*) + slot_.size() * (sizeof(void*) + 2 * sizeof(std::uint32_t));
    return bytes + sizeof(*this);
}

void BruteForce::validate() const {
    const std::size_t n = uids_.size();
    for (int a = 0; a < 3; ++a)
        if (min_[a].size() != n || max_[a].size() != n)
            throw std::logic_error("bf: box arrays and uid array differ in size");
    if (slot_.size() != n)
        throw std::logic_error("bf: uid index has " + std::to_string(slot_.size()) + " entries for " +
                               std::to_string(n) + " objects");
    for (std::size_t i = 0; i < n; ++i) {
        auto it = slot_.find(uids_[i]);
        if (it == slot_.end() || it->second != i)
            throw std::logic_error("bf: uid index does not point at slot " + std::to_string(i));
        for (int a = 0; a < 3; ++a)
            if (!(min_[a][i] <= max_[a][i]))
                throw std::logic_error("bf: uid " + std::to_string(uids_[i]) + " has min > max");
    }
}

}  // namespace rcb
