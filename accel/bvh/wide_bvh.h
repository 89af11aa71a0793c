#pragma once
/// Wide BVH: 8 child boxes per node in SoA lanes, tested with one AVX2 slab test per node, and
/// leaves of up to 8 objects stored the same way (Wald, Benthin & Boulos 2008, "Getting rid of
/// packets"; the BVH8 layout of Embree, Wald et al. 2014). Built top-down by binned SAH (Wald 2007)
/// straight into wide nodes, splitting the child with the largest box until the node is full.
/// Changes keep the tree: moves rewrite the object's lane (or reinsert the object when it left its
/// leaf's box), inserts descend to the leaf of least area growth (a full leaf splits), removes
/// empty their lane; commit refits the changed blocks in one bottom-up pass, each block once.
/// Quality is kept by a progressive rebuild, as PhysX's
/// dynamic pruner and Jolt's quad tree do: once the changes since the live tree was gathered reach
/// `rebuild_after` × the objects (a move that stays in its leaf counts its step over its size), or
/// its running SAH sum grew by `rebuild_ratio`, a next tree is
/// built from the live objects a budget of work per commit (`rebuild_speed` objects' share per
/// change), the changes meanwhile are logged and replayed into it, and the trees swap; the live tree
/// answers throughout. `threads` runs the refit and the queued moves and inserts of large frames on
/// a task arena, with the one-thread result. docs/structures.md has the details and the measurements.
///
/// This header holds the tree, its changes and its queries; the builder is in wide_bvh_build.h, the
/// progressive rebuild in wide_bvh_rebuild.h (both friends of the tree, which they build).

#include <algorithm>
#include <array>
#include <bit>
#include <cstdint>
#include <memory>
#include <tuple>
#include <vector>

#include "accel/interface/params.h"
#include "accel/interface/hit_policy.h"
#include "accel/interface/structure.h"
#include "accel/bvh/wide_bvh_build.h"
#include "accel/bvh/wide_bvh_index.h"
#include "accel/bvh/wide_bvh_rebuild.h"
#include "accel/common/query_scratch.h"

#if defined(__AVX2__)
#include <immintrin.h>
#endif

namespace rcb {

class WideBvh : public StructureBase<WideBvh, StackScratch> {
public:
    /// Params::push, parsed once by the constructor; the enumerators follow kPushChoices.
    enum class Push : std::uint8_t { automatic, fixed, loop };
    static constexpr const char* kPushChoices = "auto,fixed,loop";
    /// The field options of `push`: the tuner searches it; complete parameters leave it out at its
    /// default.
    static constexpr FieldOptions kPushOptions{.choices = kPushChoices, .recorded_when_default = false};
    /// `rebuild_every`: complete parameters leave it out at its default (off), so that
    /// configurations recorded before it existed keep their identity.
    static constexpr FieldOptions kRebuildEveryOptions{.recorded_when_default = false};
    /// Params::queue_moves, parsed once by the constructor; the enumerators follow kQueueChoices.
    enum class Queue : std::uint8_t { automatic, on, off };
    static constexpr const char* kQueueChoices = "auto,on,off";
    static constexpr FieldOptions kQueueOptions{.choices = kQueueChoices, .recorded_when_default = false};

    struct Params {
        /// Children per inner node at build time (the lanes of a node are 8 either way). 8 measured
        /// 1.3-1.5x faster rays than 4 on irreg-l, clusters-l and jittered-l.
        int width = 8;
        /// Objects per leaf at build time; a full leaf splits on insert. 8 measured fastest (rays
        /// 5-15% faster than 4, 110 against 195 B per object).
        int leaf_size = 8;
        /// SAH bins per axis of the top-down build.
        int bins = 16;
        /// A rebuild starts at commit when the SAH sum exceeds this × its value when the tree was last
        /// built or swapped in (sah_growth; 0: never).
        double rebuild_ratio = 1.5;
        /// A rebuild starts at commit once the changes since the live tree's objects were gathered
        /// for its build reach this × the object count (0: never). Inserts, removes and moves that
        /// reinsert count one each; another move counts how far its farthest face moved in units of
        /// its longest edge, at most one: a body stepping a fraction of its size every frame wears
        /// the tree's partition by that fraction, not by a whole change.
        double rebuild_after = 2.0;
        /// A rebuild starts at the commit that ends this many commits with changes since the live
        /// tree's objects were gathered, whatever changed (0: never): Embree's policy for scenes
        /// that only move, a refit per frame (RTC_BUILD_QUALITY_REFIT) and a full build every so
        /// many frames, with the reinsertions turned off (`reinsert`) for a pure refit.
        int rebuild_every = 0;
        /// A started rebuild advances by this many objects' share of its work per change of the
        /// commit, while the live tree answers (0: the whole rebuild in the commit that starts it).
        double rebuild_speed = 4.0;
        /// A move whose new centre lies outside its leaf's box (as of the last commit) reinserts the
        /// object (remove, then insert by least area growth) instead of stretching the leaf.
        bool reinsert = true;
        /// How the hit children of a node go onto the stack: one step per hit child (`loop`), or
        /// eight branch-free steps, every lane written and a hit one kept (`fixed`). The loop's
        /// exit is a branch no predictor learns, but its speculation runs ahead into the next
        /// node; that pays once the tree misses the cache and costs while it does not (measured:
        /// fixed 6-8% faster rays at 14 k objects, 1.5 MB; 3% slower at 6.7 MB, 13-34% slower at
        /// 22-110 MB). `auto`: fixed while the blocks fit in the L2 cache.
        std::string push = "auto";
        /// Whether move() queues the move for one pass at commit that prefetches the leaves of
        /// the moves ahead (`on`), or rewrites the lane at once (`off`). Queued, the cache misses
        /// of consecutive moves overlap once the blocks outgrow the cache; while they fit, the
        /// queue's copy costs more than it saves. `auto`: queued while the blocks exceed the L2
        /// cache (as `push`). The tree and its answers are the same either way.
        std::string queue_moves = "auto";
        int cast_threads = 1;
        /// Threads of the update (the refit's levels, the queued moves and inserts, in a TBB task
        /// arena kept for the tree's lifetime); the tree, its answers and its counters are the same
        /// for every count ("The update on threads" in docs/structures.md).
        int threads = 1;

        static constexpr auto fields() {
            return std::tuple{
                Field{"width", &Params::width, 2, 8, "children per inner node at build time (lanes are 8 either way)"},
                Field{"leaf_size", &Params::leaf_size, 1, 8,
                      "objects per leaf at build time (a full leaf splits on insert)"},
                Field{"bins", &Params::bins, 2, 256, "SAH bins per axis of the build", kLogScale},
                Field{"rebuild_ratio", &Params::rebuild_ratio, 0.0, 100.0,
                      "a rebuild starts at commit when the SAH sum (not divided by the root area) exceeds this x its "
                      "value when the tree was last built or swapped in (0: never; values in (0, 1] start one at "
                      "every commit that follows a change)"},
                Field{"rebuild_after", &Params::rebuild_after, 0.0, 1000.0,
                      "a rebuild starts at commit once the changes since the live tree's objects were gathered reach "
                      "this x the object count (0: never); a move that does not reinsert counts how far its "
                      "farthest face moved over its longest edge, at most 1"},
                Field{"rebuild_every", &Params::rebuild_every, 0, 100000,
                      "a rebuild starts once this many commits with changes passed since the live tree's objects "
                      "were gathered (0: never); with reinsert=false, Embree's refit and periodic rebuild",
                      kRebuildEveryOptions},
                Field{"rebuild_speed", &Params::rebuild_speed, 0.0, 1000.0,
                      "a started rebuild advances by this many objects' share of its work per change, while the "
                      "live tree answers and its changes are logged and replayed (0: the whole rebuild at once)"},
                Field{"reinsert", &Params::reinsert, 0, 1,
                      "a move whose centre leaves its leaf's box reinserts the object instead of stretching the "
                      "leaf"},
                Field{"push", &Params::push, 0, 0,
                      "how a node's hit children go onto the stack: loop (one step per hit child; its speculation "
                      "runs ahead through cache misses), fixed (eight branch-free steps; no mispredicted loop exit), "
                      "auto (fixed while the tree's blocks fit in the L2 cache)",
                      kPushOptions},
                Field{"queue_moves", &Params::queue_moves, 0, 0,
                      "moves queued and applied at commit in one pass that prefetches the leaves ahead (on), "
                      "applied at once (off), or auto (queued while the tree's blocks exceed the L2 cache)",
                      kQueueOptions},
                cast_threads_field<Params>(),
                Field{"threads", &Params::threads, 1, 64,
                      "threads of the update: the refit's levels, the queued moves' lookups, checks and lane "
                      "writes, and the queued inserts' leaf search (TBB task arena; the tree, answers and "
                      "counters are the same for every count)",
                      kNotTunedDefaultUnrecorded}};
        }
    };

    static constexpr int kLanes = kWideLanes;

    WideBvh();
    explicit WideBvh(const Params& p);

    void build(std::span<const Object> objects) override;
    void insert(const Object& object) override;
    void remove(Uid uid) override;
    void move(const Object& object) override;
    void commit() override;
    std::size_t size() const override { return where_.size() + pending_inserts_.size(); }
    std::uint64_t writes() const override { return writes_; }
    std::uint64_t update_work() const override;
    std::size_t memory_bytes() const override;
    nlohmann::json stats() const override;
    void check() const override;

    /// Expected node visits plus object tests of a ray that meets the root's box (the SAH with
    /// C_T = C_I = 1): Σ over nodes of area(node) · (1 + objects if a leaf) / area(root).
    double sah_cost() const;
    /// The SAH sum not divided by the root's area, Σ over nodes of area(node) · (1 + objects if a
    /// leaf), over the same sum right after the last build: what the rebuild policy watches. Not
    /// normalised, so that a root grown by one far object does not hide the growth of the rest.
    double sah_growth() const;
    /// Inner levels above the deepest leaf (0: the root is a leaf; -1: empty).
    int depth() const;
    /// What the updates did since the tree was made, summed (bench/wbvh_update.cpp reads them
    /// around each phase of a frame).
    struct UpdateCounts {
        std::uint64_t reinserts = 0, splits = 0, refit_blocks = 0, refit_lanes = 0, rebuild_work = 0, rebuilds = 0;
    };
    const UpdateCounts& update_counts() const { return counts_; }
    /// A hash of every block in use (lanes, links, counts, flags), the root and the free list: for
    /// tests, the same for every update thread count.
    std::uint64_t fingerprint() const;
    /// Refit levels and move queues that ran on the update arena (Params::threads) since the tree
    /// was made (for tests: the threads were used).
    std::uint64_t parallel_steps() const { return parallel_steps_; }
    /// Applies the queued moves now (commit, insert, remove and queries do it first): for
    /// bench/wbvh_update.cpp, which times them apart from the refit.
    void flush_moves() { flush(); }

    // The traversal interface of StructureBase: the deferred refit, then const traversals with a
    // stack per thread.
    void prepare() {
        flush();
        if (!dirty_.empty()) refit();
        fixed_push_ =
            push_ == Push::fixed || (push_ == Push::automatic && blocks_.size() * sizeof(Block) <= l2_bytes());
    }
    /// Popping one block pushes at most 8: at most 7 per inner level on the path plus one. The
    /// closest-hit traversal keeps each entry's entry parameter beside it: two words per entry.
    void fit(StackScratch& scratch) const { scratch.fit(2 * (7 * std::size_t(max_depth_) + 8)); }
    template <class Count, class Visit>
    void traverse(const Segment& s, Count& count, Visit&& visit, StackScratch& scratch) const {
        if constexpr (HasTLimit<std::remove_cvref_t<Visit>>)
            traverse_nearest(s, count, visit, scratch);
        else if (fixed_push_)
            traverse_with<true>(s, count, visit, scratch);
        else
            traverse_with<false>(s, count, visit, scratch);
    }

private:
    friend class WideBvhBuilder;
    friend class WideBvhRebuild;
    static constexpr std::uint32_t kNone = 0xffffffffu;

    /// The L2 data cache of this machine (sysconf), or 1 MiB where it does not say.
    static std::size_t l2_bytes();

    /// Per axis the offset of the near and far bounds in a block's `bound` array: min at 8·axis,
    /// max at 24 + 8·axis; the near side is the max when the direction is negative.
    static void bound_offsets(const SegmentSlabs& slabs, int near[3], int far[3]) {
        for (int a = 0; a < 3; ++a) {
            near[a] = (slabs.near_is_max[a] ? 24 : 0) + 8 * a;
            far[a] = (slabs.near_is_max[a] ? 0 : 24) + 8 * a;
        }
    }

    template <bool kFixedPush, class Count, class Visit>
    void traverse_with(const Segment& s, Count& count, Visit& visit, StackScratch& scratch) const {
        if (root_ == kNone) return;
        const SegmentSlabs slabs(s);
        int near[3], far[3];
        bound_offsets(slabs, near, far);
        std::uint32_t* stack = scratch.stack();
        std::uint32_t top = 0;
        stack[top++] = root_;
        alignas(32) float t_near[kLanes];
        while (top != 0) {
            const Block& b = blocks_[stack[--top]];
            count.traversal();
            count.reads(&b, sizeof b);
            unsigned mask;
            if (Count::candidates && b.leaf) {  // a leaf reached through its box: all its objects
                mask = (1u << b.count) - 1;
                for (int k = 0; k < kLanes; ++k) t_near[k] = 0;
            } else {
                mask = test(b, slabs, near, far, t_near);
            }
            if (b.leaf) {
                count.box_tests(b.count);
                while (mask != 0) {
                    const int k = __builtin_ctz(mask);
                    mask &= mask - 1;
                    count.hits();
                    if (!visit(Uid(b.ref[k]), t_near[k])) return;
                }
            } else {
                count.node_hits(unsigned(__builtin_popcount(mask)));
                // Highest lane first onto the stack, so lane order is visit order (Params::push).
                if constexpr (kFixedPush) {
                    for (int k = kLanes - 1; k >= 0; --k) {  // fit leaves room for the unkept lanes
                        stack[top] = b.ref[k];
                        top += (mask >> k) & 1u;
                    }
                } else {
                    while (mask != 0) {
                        const int k = 31 - __builtin_clz(mask);
                        mask &= ~(1u << k);
                        stack[top++] = b.ref[k];
                    }
                }
            }
        }
    }

    /// Closest hits (hit_policy.h): near to far, and nothing entered after the best hit so far is
    /// read. An inner block's nearest hit lane is read next at once, its other hit lanes go onto the
    /// stack, nearest on top, each with the entry parameter of its box (push_near_first); an entry
    /// popped after the limit dropped below it is skipped without reading its block. The slab test
    /// clips the lanes to the limit (t_far starts at min(1, limit)), so a lane entered later is
    /// neither pushed nor read. A lane's box holds its objects' boxes and both entries come from the
    /// same float slab computation, monotonic in the bounds, so no object at or before the limit is
    /// skipped (ties at the limit are kept). N_T counts the blocks tested, not the skipped pops.
    template <class Count, class Visit>
    void traverse_nearest(const Segment& s, Count& count, Visit& visit, StackScratch& scratch) const {
        if (root_ == kNone) return;
        const SegmentSlabs slabs(s);
        int near[3], far[3];
        bound_offsets(slabs, near, far);
        std::uint32_t* stack = scratch.stack();  // pairs: block, bits of its lane's entry parameter
        std::uint32_t top = 0, node = root_;
        alignas(32) float t_near[kLanes], t_far[kLanes];
        // The limit as a local, read again only after a leaf's visits: the stack's vector stores
        // may alias the visitor, which would otherwise reload it on every block's path.
        float limit = std::min(1.0f, visit_limit(visit));
        for (;;) {
            const Block& b = blocks_[node];
            count.traversal();
            count.reads(&b, sizeof b);
            unsigned mask;
            if (Count::candidates && b.leaf) {  // a leaf reached through its box: all its objects
                mask = (1u << b.count) - 1;
                for (int k = 0; k < kLanes; ++k) t_near[k] = 0;
            } else {
                mask = test(b, slabs, near, far, t_near, limit, t_far);
            }
            if (b.leaf) {
                count.box_tests(b.count);
                for (; mask != 0; mask &= mask - 1) {
                    const int k = __builtin_ctz(mask);
                    count.hits();
                    if (!visit(Uid(b.ref[k]), t_near[k])) return;
                }
                limit = std::min(1.0f, visit_limit(visit));
            } else {
                count.node_hits(unsigned(__builtin_popcount(mask)));
                if (mask != 0) {  // a single hit lane is read next: nothing to order
                    node = (mask & (mask - 1)) == 0 ? b.ref[__builtin_ctz(mask)]
                                                    : push_near_first(b, mask, t_near, t_far, stack, top);
                    continue;
                }
            }
            do {  // the next entry not beyond the limit
                if (top == 0) return;
                top -= 2;
            } while (std::bit_cast<float>(stack[top + 1]) > limit);
            node = stack[top];
        }
    }

    /// A node or a leaf: lane k holds child k's box (inner) or object k's box (leaf), minima of the
    /// three axes then maxima, 8 floats each; unused lanes hold the empty box (+inf, -inf), which
    /// no segment meets, so a block is always tested whole.
    struct alignas(32) Block {
        float bound[6][kLanes];       // 192 B: min x, y, z, max x, y, z
        std::uint32_t ref[kLanes];    // 32 B: child block (inner) or uid (leaf)
        std::uint32_t parent;         // kNone at the root; the next free block on the free list
        std::uint16_t depth;          // inner levels above this block (0 at the root)
        std::uint8_t lane_in_parent;  // this block's lane in its parent
        std::uint8_t count;           // lanes in use, 1..8 (0: free)
        bool leaf;
        bool dirty;  // on dirty_: its box in the parent is refitted at commit
        Aabb box(int k) const {
            return {{bound[0][k], bound[1][k], bound[2][k]}, {bound[3][k], bound[4][k], bound[5][k]}};
        }
        void set(int k, const Aabb& b) {
            for (int a = 0; a < 3; ++a) bound[a][k] = b.min[a], bound[3 + a][k] = b.max[a];
        }
        void clear(int k);
        /// The union of the lanes in use.
        Aabb bounds() const;
    };
    static_assert(sizeof(Block) == 256);

    /// The hit lanes (`mask`; the caller reads a single one next itself) of inner block `b`, with
    /// test()'s `t_near` and `t_far` of it (the AVX2 path compares them again for the lanes):
    /// returns the nearest's block and puts the others onto a closest-hit stack with their entry
    /// parameters, the farthest first so that the nearest is popped first. Equal entries, as where
    /// the segment starts inside several boxes, go by exit: the box the segment leaves first is
    /// taken first, as its objects lie nearer along it. The order only decides which block is read
    /// first, never the answer.
#if defined(__AVX2__)
    /// Branch-free, as a data-dependent sort mispredicts on most nodes of incoherent rays: one
    /// 32-bit key per lane, sorted by a bitonic network in one register (Batcher 1968); the lanes'
    /// refs and entries permuted into that order and all 8 pairs stored, `top` then keeping the
    /// hit ones but the nearest. The nearest comes from a shorter reduction beside the sort, as the
    /// next block's address waits for it. The key: entries are in [0, 1], so their bits order as
    /// integers; lanes entered at 0 take their exit's bits halved, below every positive entry's;
    /// the low 3 bits hold the lane (unique keys; the rounding only reorders near-ties); missed
    /// lanes have the sign bit set (last in the signed sort, never the unsigned minimum).
    [[gnu::always_inline]] static std::uint32_t push_near_first(const Block& b, unsigned mask, const float* t_near,
                                                                const float* t_far, std::uint32_t* stack,
                                                                std::uint32_t& top) {
        const __m256 tn = _mm256_load_ps(t_near), tf = _mm256_load_ps(t_far);
        // The hit lanes as the slab test's own comparison, which the compiler shares with it: the
        // keys need not wait for the mask to go to a general register and back.
        const __m256i hit = _mm256_castps_si256(_mm256_cmp_ps(tn, tf, _CMP_LE_OQ));
        const __m256i tn_bits = _mm256_castps_si256(tn);
        const __m256i entered = _mm256_or_si256(tn_bits, _mm256_set1_epi32(0x40000000));
        const __m256i inside = _mm256_srli_epi32(_mm256_castps_si256(tf), 1);
        const __m256 at_start = _mm256_cmp_ps(tn, _mm256_setzero_ps(), _CMP_EQ_OQ);
        __m256i key = _mm256_blendv_epi8(entered, inside, _mm256_castps_si256(at_start));
        key =
            _mm256_or_si256(_mm256_andnot_si256(_mm256_set1_epi32(7), key), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
        key = _mm256_or_si256(key, _mm256_andnot_si256(hit, _mm256_set1_epi32(INT32_MIN)));

        __m256i least = _mm256_min_epu32(key, _mm256_shuffle_epi32(key, 0xb1));
        least = _mm256_min_epu32(least, _mm256_shuffle_epi32(least, 0x4e));
        least = _mm256_min_epu32(least, _mm256_permute2x128_si256(least, least, 1));
        const std::uint32_t nearest = b.ref[_mm256_cvtsi256_si32(least) & 7];

        const __m256i order = _mm256_and_si256(sort_descending(key), _mm256_set1_epi32(7));
        const __m256i refs =
            _mm256_permutevar8x32_epi32(_mm256_load_si256(reinterpret_cast<const __m256i*>(b.ref)), order);
        const __m256i entries = _mm256_permutevar8x32_epi32(tn_bits, order);
        const __m256i lo = _mm256_unpacklo_epi32(refs, entries), hi = _mm256_unpackhi_epi32(refs, entries);
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(stack + top), _mm256_permute2x128_si256(lo, hi, 0x20));
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(stack + top + 8), _mm256_permute2x128_si256(lo, hi, 0x31));
        top += 2 * unsigned(__builtin_popcount(mask)) - 2;
        return nearest;
    }
    /// The 8 keys of `v` in descending order: the bitonic network's six layers of compare-exchange,
    /// each a shuffle, a min, a max and a blend; one layer crosses the 128-bit halves.
    [[gnu::always_inline]] static __m256i sort_descending(__m256i v) {
        v = exchange<0x99>(v, _mm256_shuffle_epi32(v, 0xb1));       // pairs (2i, 2i+1), alternating
        v = exchange<0xc3>(v, _mm256_shuffle_epi32(v, 0x4e));       // bitonic 4-merges, distance 2
        v = exchange<0xa5>(v, _mm256_shuffle_epi32(v, 0xb1));       // distance 1
        v = exchange<0x0f>(v, _mm256_permute2x128_si256(v, v, 1));  // 8-merge, distance 4
        v = exchange<0x33>(v, _mm256_shuffle_epi32(v, 0x4e));       // distance 2
        v = exchange<0x55>(v, _mm256_shuffle_epi32(v, 0xb1));       // distance 1
        return v;
    }
    /// One compare-exchange layer: lane i keeps max(v, partner) when bit i of kTakeMax is set,
    /// else the min.
    template <int kTakeMax>
    [[gnu::always_inline]] static __m256i exchange(__m256i v, __m256i partner) {
        return _mm256_blend_epi32(_mm256_min_epi32(v, partner), _mm256_max_epi32(v, partner), kTakeMax);
    }
#else
    [[gnu::always_inline]] static std::uint32_t push_near_first(const Block& b, unsigned mask, const float* t_near,
                                                                const float* t_far, std::uint32_t* stack,
                                                                std::uint32_t& top) {
        auto nearer = [&](int a, int c) {
            return t_near[a] < t_near[c] || (t_near[a] == t_near[c] && t_far[a] < t_far[c]);
        };
        int lanes[kLanes], n = 0;
        for (; mask != 0; mask &= mask - 1) {  // insertion by entry: a node has few hit lanes
            const int k = __builtin_ctz(mask);
            int i = n++;  // farthest first
            for (; i > 0 && nearer(lanes[i - 1], k); --i) lanes[i] = lanes[i - 1];
            lanes[i] = k;
        }
        for (int i = 0; i + 1 < n; ++i) {
            stack[top++] = b.ref[lanes[i]];
            stack[top++] = std::bit_cast<std::uint32_t>(t_near[lanes[i]]);
        }
        return b.ref[lanes[n - 1]];
    }
#endif

    /// The slab test of a block's 8 lanes: bit k set when lane k is hit, t_near[k] its entry
    /// parameter. SegmentSlabs::clip exactly: the same float operations in the same order, and
    /// VMAXPS/VMINPS return their second operand when either is NaN, as max_ignoring_nan(lo, tn).
    /// `t_max` (at most 1) clips the segment's far end, as SegmentSlabs::clip's; `t_far`, when
    /// given, receives each lane's exit parameter.
    static unsigned test(const Block& b, const SegmentSlabs& s, const int near[3], const int far[3],
                         float t_near[kLanes], float t_max = 1.0f, float* t_far = nullptr) {
#if defined(__AVX2__)
        const float* base = &b.bound[0][0];
        __m256 tn = _mm256_setzero_ps(), tf = _mm256_set1_ps(t_max);
        for (int a = 0; a < 3; ++a) {
            const __m256 o = _mm256_set1_ps(s.origin[a]), inv = _mm256_set1_ps(s.inv[a]);
            const __m256 lo = _mm256_mul_ps(_mm256_sub_ps(_mm256_load_ps(base + near[a]), o), inv);
            const __m256 hi = _mm256_mul_ps(_mm256_sub_ps(_mm256_load_ps(base + far[a]), o), inv);
            tn = _mm256_max_ps(lo, tn);
            tf = _mm256_min_ps(hi, tf);
        }
        _mm256_store_ps(t_near, tn);
        if (t_far) _mm256_store_ps(t_far, tf);
        return unsigned(_mm256_movemask_ps(_mm256_cmp_ps(tn, tf, _CMP_LE_OQ)));
#else
        (void)near, (void)far;
        unsigned mask = 0;
        for (int k = 0; k < kLanes; ++k) {
            float tf;
            if (s.clip(b.box(k), t_near[k], tf, 0.0f, t_max)) mask |= 1u << k;
            if (t_far) t_far[k] = tf;
        }
        return mask;
#endif
    }

    /// A move not yet applied: move() only checks the uid and queues it, and the queue is applied
    /// in order before anything else reads or changes the tree (commit, insert, remove, a query).
    struct PendingMove {
        Uid uid;
        Aabb box;
    };
    /// Applies the queued moves in their order, prefetching the leaf of the move kAhead places on:
    /// a physics frame moves nearly every object in uid order, so consecutive moves land in
    /// scattered leaves, and once the blocks outgrow the cache each move waited for its leaf in
    /// turn. Prefetched, the misses of several moves overlap (as Embree's refit and PhysX's
    /// batched updates walk their arrays, where a call per object leaves no look-ahead).
    void apply_moves();
    /// One move (the former move()): rewrites the object's lane, or reinserts it (Params::reinsert).
    void apply_move(std::uint32_t at, Uid uid, const Aabb& box);
    /// Whether a move of an object of leaf `b` to `box` reinserts it (Params::reinsert): its new
    /// centre lies outside the leaf's lane in its parent.
    bool leaves_leaf(std::uint32_t b, const Aabb& box) const;
    /// The queued inserts, then the queued moves (every queued insert came before every queued move:
    /// insert() applies the moves first).
    void flush() {
        if (!pending_inserts_.empty()) apply_inserts();
        if (!pending_.empty()) apply_moves();
    }
    /// Applies the queued inserts in their order (Params::threads: their leaves looked for on the
    /// arena first; wide_bvh.cpp).
    void apply_inserts();
    /// Params::queue_moves as resolved for the tree's size (at build and at every commit).
    void resolve_queue() {
        queue_ = queue_mode_ == Queue::on ||
                 (queue_mode_ == Queue::automatic && blocks_.size() * sizeof(Block) > l2_bytes());
    }
    std::uint32_t allocate();
    void release(std::uint32_t b);
    void mark(std::uint32_t b);
    void refit();

    // ---- the update on several threads (Params::threads; wide_bvh.cpp) ----
    /// Queues (a refit level, the queued moves) shorter than this stay on the calling thread:
    /// entering the arena would cost more.
    static constexpr std::size_t kParallelUpdate = 1024;
    /// The same for queued inserts, whose leaf search alone is a descent of the whole tree.
    static constexpr std::size_t kParallelInserts = 128;
    /// Calls f(begin, end) over [0, n) cut into chunks, on the update arena's threads.
    template <class F>
    void in_chunks(std::size_t n, F&& f);
    /// What refit() does for one block, computed on any thread: its box, its parent's lane
    /// rewritten when it changed, and the SAH terms for the calling thread to add in queue order.
    struct RefitRecord {
        double before = 0, after = 0;  // the lane's SAH term before and after (state 2)
        std::uint32_t parent = 0;
        std::uint8_t state = 0;  // 0: the root (nothing), 1: its box unchanged, 2: its lane rewritten
    };
    /// One level of refit() on the arena: the blocks of `queue` (each listed once) in chunks, then
    /// the sums, counters and the parents queued into `up` in queue order, as refit() does them.
    void refit_level_parallel(std::vector<std::uint32_t>& queue, std::vector<std::uint32_t>* up);
    /// One block of a refit level, on any thread: its bounds into its lane of the parent (a level
    /// up, which nothing reads meanwhile), and what changed. Inlined: refit()'s loop calls it for
    /// every refitted block.
    [[gnu::always_inline]] inline RefitRecord refit_block(std::uint32_t c);
    /// refit()'s bookkeeping of one block, in queue order on the calling thread: the counters, the
    /// SAH sums, and the parent queued into `up` once.
    void count_refit(const RefitRecord& r, std::vector<std::uint32_t>* up);
    /// Drops the repeats of a block from dirty_ (a block released and reused after it was marked),
    /// which a parallel level must not see twice.
    void unique_dirty();
    /// apply_moves() on the arena; the tree and its counters are the sequential pass's
    /// (wide_bvh.cpp has how).
    void apply_moves_parallel();
    /// The plan of apply_moves_parallel(): the leaves the queue's reinsertions touch, up to the
    /// first move it cannot foresee, whose index it returns.
    std::size_t plan_moves();
    /// The heap memory of refit_levels_.
    std::size_t refit_levels_bytes() const {
        std::size_t bytes = refit_levels_.capacity() * sizeof(std::vector<std::uint32_t>);
        for (const auto& level : refit_levels_) bytes += level.capacity() * sizeof(std::uint32_t);
        return bytes;
    }
    /// The whole rebuild at once: gather, build, done.
    void rebuild();
    /// Empties the tree (blocks, index, counters), keeping the build state.
    void clear_tree();
    /// Hooks block `b` into lane `lane` of `parent` (or makes it the root) and adds its SAH term.
    void link(std::uint32_t b, std::uint32_t parent, int lane);

    /// The leaf a new box goes to: the child of least area growth at every level. With `path`, the
    /// blocks it reads are written there, the root first and the leaf last.
    std::uint32_t choose_leaf(const Aabb& box, std::uint32_t* path = nullptr) const;
    void insert_object(const Object& o);
    /// insert_object() into a non-empty tree once the leaf is chosen.
    void insert_into(std::uint32_t leaf, const Object& o);
    /// While apply_inserts() runs on the arena: block `b`'s lanes or children change (a leaf split),
    /// so a leaf chosen through it beforehand is chosen again.
    void note_changed(std::uint32_t b) {
        if (b / 64 < inner_changed_.size()) inner_changed_[b / 64] |= std::uint64_t(1) << (b % 64);
    }
    /// A move whose centre left its leaf's box (Params::reinsert): a remove and an insert. Apart
    /// from move(), which stays a lane's write for the moves that keep their leaf.
    [[gnu::noinline]] void reinsert(Uid uid, const Aabb& box);
    void remove_object(Uid uid);
    /// Adds `o` to the full leaf `leaf`: the nine objects split in two leaves, side by side in the
    /// parent when it has a free lane, else below a new inner node in the leaf's place.
    void split_leaf(std::uint32_t leaf, const Object& o);
    /// Writes `box` into lane `k` of `b` and keeps the running SAH sum.
    void set_lane(std::uint32_t b, int k, const Aabb& box);
    /// Removes lane `k` of inner block `b` (its child already released or moved): the last lane
    /// takes its place.
    void drop_child_lane(std::uint32_t b, int k);
    double weight(std::uint32_t b) const { return 1.0 + (blocks_[b].leaf ? double(blocks_[b].count) : 0.0); }
    /// Unlinks the empty block `b` from its parent (and the parent, if that empties it).
    void remove_block(std::uint32_t b);
    /// Raises max_depth_ to `depth` (the traversal stack follows in fit()).
    void grow_stack(int depth) { max_depth_ = std::max(max_depth_, depth); }
    /// Σ area(lane) · weight(child) over all non-root blocks, recomputed from the tree.
    double fresh_sah_sum() const;
    double total_sah() const;
    /// The checks of check() on this tree alone; `refitted` false (the next tree of a rebuild,
    /// while changes are replayed into it): lanes need not enclose their children yet.
    void check_tree(bool refitted) const;
    /// Whether a commit starts a rebuild (Params::rebuild_ratio, rebuild_after).
    bool rebuild_due() const;

    Params params_;
    Push push_;
    Queue queue_mode_;
    bool queue_ = false;  // move() queues (Params::queue_moves, resolved by resolve_queue())
    std::vector<Block> blocks_;
    std::uint32_t root_ = kNone;
    std::uint32_t free_ = kNone;
    std::uint32_t free_count_ = 0;
    std::uint32_t leaves_ = 0;
    /// uid → block · 8 + lane (wide_bvh_index.h).
    WideBvhIndex where_;
    std::vector<std::uint32_t> dirty_;
    std::vector<PendingMove> pending_;  // moves queued since the last apply_moves()
    /// The refit's queues, one per depth (empty between refits; kept for their capacity).
    std::vector<std::vector<std::uint32_t>> refit_levels_;
    int max_depth_ = 0;        // an upper bound on every block's depth (sizes the stack)
    bool fixed_push_ = false;  // Params::push as prepare() resolved it for the tree's size
    // Running SAH: Σ over non-root blocks of area(its lane in the parent) · weight (double: areas
    // of boxes near the coordinate limit overflow float).
    double sah_sum_ = 0.0;
    // The largest term added to or taken from sah_sum_ since it was last recomputed: when it dwarfs
    // the sum (a huge box left the tree), rounding could dominate, so commit recomputes the sum.
    double sah_largest_term_ = 0.0;
    double total_after_build_ = 0.0;  // total_sah() right after the last build or swap
    bool changed_ = false;            // changes since the last commit
    std::uint64_t changes_ = 0;       // changes since the last commit
    // The same weighted for the rebuild trigger: inserts, removes and reinserting moves count one,
    // other moves their share (move_share in wide_bvh.cpp, Params::rebuild_after).
    // Moves are weighed only while rebuild_after > 0 (nothing else reads the weight).
    double weighted_changes_ = 0;
    double age_ = 0;             // weighted changes since the live tree's objects were gathered
    std::uint32_t commits_ = 0;  // commits with changes since the live tree's objects were gathered
    UpdateCounts counts_;        // summed since construction
    // Stats.
    std::uint32_t rebuilds_ = 0, splits_ = 0, reinserts_ = 0;
    // Blocks refitted and parent lanes rewritten since the last commit began (stats).
    std::uint64_t refit_blocks_ = 0, refit_lanes_ = 0;
    /// writes(): one per block allocated (a build writes each so), freed or refitted, per lane a change
    /// or refit rewrites, and those of a progressive rebuild's next tree as it is built and replayed.
    std::uint64_t writes_ = 0;
    /// Per object inserted or reinserted into a tree, the blocks on the path from the root to the
    /// leaf it enters (the descent of choose_leaf() that chose it, whose reads no write counts; a
    /// reinsertion is a move whose centre left its leaf). update_work() adds the rebuilds' work.
    std::uint64_t update_work_ = 0;

    // The update's threads (Params::threads > 1) and its scratch, kept between commits.
    std::unique_ptr<CastArena> update_arena_;
    std::vector<RefitRecord> refit_records_;
    bool dirty_repeats_ = false;  // a marked block was released: dirty_ may list it twice
    std::uint64_t parallel_steps_ = 0;
    // Per queued move: its slot before the queue, whether it reinserts, its weight for the rebuild
    // trigger; bits per slot and per leaf for the plan, and the counts it foresees for the leaves.
    std::vector<std::uint32_t> move_slot_;
    std::vector<std::uint8_t> move_reinserts_;
    std::vector<double> move_weight_;
    std::vector<std::uint64_t> slot_seen_, block_touched_;
    std::vector<std::uint8_t> leaf_count_;  // per block whose bit is set in block_touched_
    // Inserts queued while the update has threads (applied before anything reads the tree), the
    // blocks each one's choose_leaf() read (a stride of max_depth_ + 1, kNone after the leaf), and
    // the blocks a leaf split changed since (bits; empty while no parallel insert runs).
    std::vector<Object> pending_inserts_;
    std::vector<std::uint32_t> insert_paths_;
    std::vector<std::uint64_t> inner_changed_;

    WideBvhBuilder builder_;  // builds this tree
    WideBvhRebuild rebuild_;  // builds the next one while this one answers
};

}  // namespace rcb
