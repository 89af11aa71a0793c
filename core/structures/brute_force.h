#pragma once
/// Brute force (thesis §4.1): every object's box is tested against every ray. The baseline every
/// speed-up is measured against, so it must be honest: boxes in a structure-of-arrays layout, the
/// near and far planes chosen once per ray by the direction's signs (Williams et al. 2005), and a
/// branch-free inner loop over blocks of objects that the compiler vectorises.

#include <array>
#include <cstdint>
#include <cstring>
#include <tuple>

#include "core/structure.h"
#include "core/structures/common/slot_boxes.h"

namespace rcb {

class BruteForce : public StructureBase<BruteForce> {
public:
    struct Params {
        static constexpr auto fields() { return std::tuple{}; }
    };

    explicit BruteForce(const Params& = {}) {}

    void build(std::span<const Object> objects) override;
    void insert(const Object& object) override;
    void remove(Uid uid) override;
    void move(const Object& object) override;
    std::size_t size() const override { return objects_.size(); }
    std::size_t memory_bytes() const override;
    void validate() const override;

    template <class Count, class Visit>
    void traverse(const Segment& s, Count& count, Visit&& visit);

private:
    /// Objects tested per block: the flags of one block stay in L1.
    static constexpr std::size_t kBlock = 1024;

    /// Tests boxes [begin, end) and writes 1 (hit) or 0 per box into `hit_`, zeros up to a multiple
    /// of eight after them.
    void test_block(const SegmentSlabs& slabs, std::size_t begin, std::size_t end);

    SoaSlotBoxes objects_;
    // Per-block scratch of the query: hit flags, read back eight at a time.
    alignas(8) std::array<std::uint8_t, kBlock> hit_{};
};

template <class Count, class Visit>
void BruteForce::traverse(const Segment& s, Count& count, Visit&& visit) {
    const SegmentSlabs slabs(s);
    const std::size_t n = objects_.size();
    count.box_tests(n);
    for (std::size_t begin = 0; begin < n; begin += kBlock) {
        const std::size_t end = std::min(n, begin + kBlock);
        test_block(slabs, begin, end);
        // Hits are rare: eight flags per load, and a hit's entry t recomputed by the same slab test
        // (the same operations, so the same t) instead of storing t for every box.
        for (std::size_t i = 0; i < end - begin; i += 8) {
            std::uint64_t word;
            std::memcpy(&word, hit_.data() + i, sizeof word);
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
