#pragma once
/// Brute force (thesis §4.1): every object's box is tested against every ray. The baseline every
/// speed-up is measured against, so it must be honest: boxes in a structure-of-arrays layout, the
/// near and far planes chosen once per ray by the direction's signs (Williams et al. 2005), and
/// eight slab tests per AVX2 instruction (without AVX2, blocks the compiler vectorises).

#include <array>
#include <cstdint>
#include <cstring>
#include <tuple>

#ifdef __AVX2__
#include <immintrin.h>
#endif

#include "accel/interface/structure.h"
#include "accel/common/slot_boxes.h"

namespace rcb {

/// A query's hit flags for one block of boxes (per thread: structure.h).
struct alignas(64) BruteForceScratch {
    /// Objects tested per block: the flags of one block stay in L1.
    static constexpr std::size_t kBlock = 1024;
    alignas(8) std::array<std::uint8_t, kBlock> hit{};
    std::size_t memory_bytes() const { return 0; }  // all in sizeof
};

class BruteForce : public StructureBase<BruteForce, BruteForceScratch> {
public:
    struct Params {
        int cast_threads = 1;
        static constexpr auto fields() { return std::tuple{cast_threads_field<Params>()}; }
    };

    BruteForce() : BruteForce(Params{}) {}
    explicit BruteForce(const Params& p) { set_cast_threads(p.cast_threads); }

    void build(std::span<const Object> objects) override;
    void insert(const Object& object) override;
    void remove(Uid uid) override;
    void move(const Object& object) override;
    std::size_t size() const override { return objects_.size(); }
    std::size_t memory_bytes() const override;
    void check() const override;

    // The traversal interface of StructureBase.
    void prepare() {}
    void fit(BruteForceScratch&) const {}
    template <class Count, class Visit>
    void traverse(const Segment& s, Count& count, Visit&& visit, BruteForceScratch& scratch) const;

private:
    static constexpr std::size_t kBlock = BruteForceScratch::kBlock;

    /// Tests boxes [begin, end) and writes 1 (hit) or 0 per box into `hit`, zeros up to a multiple
    /// of eight after them.
    void test_block(const SegmentSlabs& slabs, std::size_t begin, std::size_t end, std::uint8_t* hit) const;

    SoaSlotBoxes objects_;
};

template <class Count, class Visit>
void BruteForce::traverse(const Segment& s, Count& count, Visit&& visit, BruteForceScratch& scratch) const {
    const SegmentSlabs slabs(s);
    const std::size_t n = objects_.size();
    if constexpr (Count::candidates) {  // no test at all: every object is a candidate
        for (std::uint32_t slot = 0; slot < n; ++slot) {
            count.hits();
            if (!visit(objects_.uid(slot), 0.0f)) return;
        }
        return;
    }
    count.box_tests(n);
    std::size_t done = 0;
#ifdef __AVX2__
    // Eight slab tests per instruction straight from the SoA arrays, hits taken from the lane mask:
    // the plainest fast loop (bench/bf_baseline times it against one written outside rcbench). The
    // operations and their order are SegmentSlabs::clip's (max/min return their second operand for
    // a NaN, as max_ignoring_nan does), so hits and t are the same as the scalar test's.
    {
        const float* near[3];
        const float* far[3];
        __m256 origin[3], inv[3];
        for (int a = 0; a < 3; ++a) {
            const float* lo = objects_.layout().min(a);
            const float* hi = objects_.layout().max(a);
            near[a] = slabs.near_is_max[a] ? hi : lo;
            far[a] = slabs.near_is_max[a] ? lo : hi;
            origin[a] = _mm256_set1_ps(slabs.origin[a]);
            inv[a] = _mm256_set1_ps(slabs.inv[a]);
        }
        for (; done + 8 <= n; done += 8) {
            __m256 tn = _mm256_setzero_ps(), tf = _mm256_set1_ps(1.0f);
            for (int a = 0; a < 3; ++a) {
                const __m256 lo = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(near[a] + done), origin[a]), inv[a]);
                const __m256 hi = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(far[a] + done), origin[a]), inv[a]);
                tn = _mm256_max_ps(lo, tn);
                tf = _mm256_min_ps(hi, tf);
            }
            unsigned mask = unsigned(_mm256_movemask_ps(_mm256_cmp_ps(tn, tf, _CMP_LE_OQ)));
            if (!mask) continue;
            alignas(32) float t[8];
            _mm256_store_ps(t, tn);
            for (; mask; mask &= mask - 1) {
                const unsigned lane = unsigned(__builtin_ctz(mask));
                count.hits();
                if (!visit(objects_.uid(std::uint32_t(done + lane)), t[lane])) return;
            }
        }
    }
#endif
    // Without AVX2, and for the last boxes: blocks the compiler vectorises, then the flags eight at
    // a time; hits are rare, so a hit's t is recomputed by the same slab test instead of stored.
    for (std::size_t begin = done; begin < n; begin += kBlock) {
        const std::size_t end = std::min(n, begin + kBlock);
        test_block(slabs, begin, end, scratch.hit.data());
        for (std::size_t i = 0; i < end - begin; i += 8) {
            std::uint64_t word;
            std::memcpy(&word, scratch.hit.data() + i, sizeof word);
            for (; word; word &= word - 1) {
                const auto slot = std::uint32_t(begin + i + std::size_t(__builtin_ctzll(word) >> 3));
                float t_near, t_far;
                slabs.clip(objects_.box(slot), t_near, t_far);
                count.hits();
                if (!visit(objects_.uid(slot), t_near)) return;
            }
        }
    }
}

}  // namespace rcb
