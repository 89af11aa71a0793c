#include "accel/scan/brute_force.h"

#include <algorithm>

namespace rcb {

void BruteForce::build(std::span<const Object> objects) {
    objects_.clear();
    objects_.reserve(objects.size());
    for (const Object& o : objects) objects_.insert(o);
}

void BruteForce::insert(const Object& o) { objects_.insert(o); }
void BruteForce::remove(Uid uid) { objects_.remove(uid); }
void BruteForce::move(const Object& o) { objects_.move(o); }

namespace {

/// The slab test of SegmentSlabs::clip over arrays of near and far planes, unrolled over the axes
/// so that it vectorises (a free function with restrict pointers: GCC 12 does not vectorise it as
/// a member). The operand order of each min/max keeps the NaN-dropping semantics of geometry.h.
void slab_test_boxes(const float* __restrict nx, const float* __restrict ny, const float* __restrict nz,
                     const float* __restrict fx, const float* __restrict fy, const float* __restrict fz, float ox,
                     float oy, float oz, float ix, float iy, float iz, std::size_t n, std::uint8_t* __restrict hit) {
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
    }
}

}  // namespace

void BruteForce::test_block(const SegmentSlabs& slabs, std::size_t begin, std::size_t end, std::uint8_t* hit) const {
    const float* near[3];
    const float* far[3];
    for (int a = 0; a < 3; ++a) {
        const float* lo = objects_.layout().min(a);
        const float* hi = objects_.layout().max(a);
        near[a] = (slabs.near_is_max[a] ? hi : lo) + begin;
        far[a] = (slabs.near_is_max[a] ? lo : hi) + begin;
    }
    slab_test_boxes(near[0], near[1], near[2], far[0], far[1], far[2], slabs.origin.x, slabs.origin.y, slabs.origin.z,
                    slabs.inv.x, slabs.inv.y, slabs.inv.z, end - begin, hit);
    const std::size_t n = end - begin, padded = (n + 7) / 8 * 8;
    std::fill(hit + n, hit + padded, std::uint8_t(0));
}

std::size_t BruteForce::memory_bytes() const { return objects_.memory_bytes() + sizeof(*this) + scratch_bytes(); }

void BruteForce::check() const { objects_.check("bf"); }

}  // namespace rcb
