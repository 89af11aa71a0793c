#include "accel/bvh/linear_bvh.h"

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <numeric>
#include <stdexcept>
#include <string>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "accel/common/outlier_trim.h"

#ifdef __BMI2__
#include <immintrin.h>
#endif

namespace rcb {

// Every per-chunk array holds the chunks of the most threads Params::threads allows.
static_assert(LinearBvh::kMaxChunks >=
              std::size_t(std::get<0>(LinearBvh::Params::fields()).hi) * LinearBvh::kChunksPerThread);

struct LinearBvh::Arena {
    explicit Arena(int threads) : arena(threads) {}
    tbb::task_arena arena;
};

namespace {

/// Spreads the low 21 bits of v to every third bit: one pdep where BMI2 is there, else the classic
/// magic-number interleave (the same result).
std::uint64_t spread_bits(std::uint32_t v) {
#ifdef __BMI2__
    return _pdep_u64(v, 0x1249249249249249ull);
#else
    std::uint64_t x = v & 0x1fffffu;
    x = (x | x << 32) & 0x1f00000000ffffull;
    x = (x | x << 16) & 0x1f0000ff0000ffull;
    x = (x | x << 8) & 0x100f00f00f00f00full;
    x = (x | x << 4) & 0x10c30c30c30c30c3ull;
    x = (x | x << 2) & 0x1249249249249249ull;
    return x;
#endif
}

/// The Morton grid of the centroid bounds `bounds`: each axis quantised to 21 bits, the three
/// interleaved into a 63-bit code. One definition for the radix path and resort(), whose codes must
/// be equal bit for bit.
struct MortonGrid {
    static constexpr float kMax = float((1u << 21) - 1);
    Aabb bounds;
    Vec3 scale;
    explicit MortonGrid(const Aabb& b) : bounds(b) {
        for (int a = 0; a < 3; ++a) {
            const float ext = b.max[a] - b.min[a];
            scale[a] = ext > 0 ? kMax / ext : 0.0f;
        }
    }
    std::uint64_t code(const Vec3& m) const {
        // In [0, 2^21): the conversion to 32 bits truncates as one to 64 bits would.
        const auto qx = std::uint32_t(std::clamp((m.x - bounds.min.x) * scale.x, 0.0f, kMax));
        const auto qy = std::uint32_t(std::clamp((m.y - bounds.min.y) * scale.y, 0.0f, kMax));
        const auto qz = std::uint32_t(std::clamp((m.z - bounds.min.z) * scale.z, 0.0f, kMax));
        return spread_bits(qx) << 2 | spread_bits(qy) << 1 | spread_bits(qz);
    }
};

/// Insertion sort of the n keys sk[0, n) (payload sv) into k[0, n) (payload v). sk may be k and sv
/// v (in place): key i is read before any write reaches it.
void insertion_sort(const std::uint64_t* sk, const std::uint32_t* sv, std::uint64_t* k, std::uint32_t* v,
                    std::size_t n) {
    for (std::size_t i = 0; i < n; ++i) {
        const std::uint64_t key = sk[i];
        const std::uint32_t val = sv[i];
        std::size_t j = i;
        for (; j > 0 && k[j - 1] > key; --j) k[j] = k[j - 1], v[j] = v[j - 1];
        k[j] = key, v[j] = val;
    }
}

// The sort: one most-significant-digit pass of kTopBits over all keys, then each bucket on its own
// with kSubBits digits, down to runs of kInsertion keys, which an insertion sort finishes.
constexpr int kTopBits = 11;
constexpr std::uint32_t kTopDigits = 1u << kTopBits;
constexpr int kSubBits = 8;
constexpr std::size_t kInsertion = 32;

/// Stable sort of k[0, n) (payload v) on their low `bits` bits (the bits above are equal); tk and
/// tv are scratch of n. A bucket of 2 000 keys and its scratch fit in the L1/L2 caches, which is
/// what makes this cheaper than more passes over all keys (Satish, Harris & Garland 2009, "Designing
/// efficient sorting algorithms for manycore GPUs", use the same local-buckets idea).
void sort_bucket(std::uint64_t* k, std::uint32_t* v, std::uint64_t* tk, std::uint32_t* tv, std::size_t n, int bits) {
    while (bits > 0 && n > 1) {
        if (n <= kInsertion) {
            insertion_sort(k, v, k, v, n);
            return;
        }
        const int d = std::min(bits, kSubBits), shift = bits - d;
        const std::uint32_t mask = (1u << d) - 1;
        std::uint32_t count[1u << kSubBits] = {};
        for (std::size_t i = 0; i < n; ++i) ++count[(k[i] >> shift) & mask];
        bits = shift;
        if (count[(k[0] >> shift) & mask] == n) continue;  // one digit: nothing moves
        std::uint32_t at[1u << kSubBits], sum = 0, largest = 0;
        for (std::uint32_t g = 0; g <= mask; ++g) at[g] = sum, sum += count[g], largest = std::max(largest, count[g]);
        for (std::size_t i = 0; i < n; ++i) {
            const std::uint32_t j = at[(k[i] >> shift) & mask]++;
            tk[j] = k[i], tv[j] = v[i];
        }
        if (largest <= kInsertion) {
            // Every digit's keys are few (the common case of a top bucket: about 500 keys over
            // 256 digits): one insertion pass copies them back in order. A key only passes keys
            // of its own digit, so this costs about as much as the copy, and replaces a call per
            // digit.
            insertion_sort(tk, tv, k, v, n);
            return;
        }
        std::copy_n(tk, n, k);
        std::copy_n(tv, n, v);
        for (std::uint32_t g = 0, b = 0; g <= mask; b += count[g++])
            if (count[g] > 1) sort_bucket(k + b, v + b, tk + b, tv + b, count[g], bits);
        return;
    }
}

}  // namespace

LinearBvh::LinearBvh() : LinearBvh(Params{}) {}

LinearBvh::LinearBvh(const Params& p) : params_(p) {
    if (params_.threads > 1) arena_ = std::make_unique<Arena>(params_.threads);
    set_cast_threads(params_.cast_threads);
}

LinearBvh::~LinearBvh() = default;

template <class F>
void LinearBvh::parallel(std::size_t n, std::size_t grain, F&& f) {
    if (!arena_ || n <= grain) {
        f(std::size_t(0), n);
        return;
    }
    arena_->arena.execute([&] {
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, grain),
                          [&](const tbb::blocked_range<std::size_t>& r) { f(r.begin(), r.end()); });
    });
}

void LinearBvh::build(std::span<const Object> objects) {
    objects_.clear();
    objects_.reserve(objects.size());
    for (const Object& o : objects) objects_.insert(o);
    changes_ = kNoOrder;  // new slots: the last order says nothing about them
    centroids_moved_ = true;
    rebuilds_since_crowd_check_ = kCrowdCheckEvery;  // look for crowds in the first tree
    rebuild();
}

/// The centroid bounds of the last rebuild stay exact while no centre leaves them and none on
/// their faces goes (a conservative test: a centre on a face may have a twin there).
namespace {
bool inside(const Vec3& c, const Aabb& b) {
    return b.min.x <= c.x && c.x <= b.max.x && b.min.y <= c.y && c.y <= b.max.y && b.min.z <= c.z && c.z <= b.max.z;
}
bool strictly_inside(const Vec3& c, const Aabb& b) {
    return b.min.x < c.x && c.x < b.max.x && b.min.y < c.y && c.y < b.max.y && b.min.z < c.z && c.z < b.max.z;
}
}  // namespace

void LinearBvh::insert(const Object& o) {
    objects_.insert(o);
    ++changes_;
    centroids_moved_ |= !inside(o.box.center(), centroid_bounds_);
    dirty_ = true;
}

void LinearBvh::remove(Uid uid) {
    Aabb old;
    objects_.remove(uid, &old);
    ++changes_;
    centroids_moved_ |= !strictly_inside(old.center(), centroid_bounds_);
    dirty_ = true;
}

void LinearBvh::move(const Object& o) {
    Aabb old;
    objects_.move(o, &old);
    ++changes_;
    centroids_moved_ |= !strictly_inside(old.center(), centroid_bounds_) || !inside(o.box.center(), centroid_bounds_);
    dirty_ = true;
}

void LinearBvh::commit() {
    if (dirty_) rebuild();
}

/// Stable radix sort of codes_ with their slots as payload (into order_), most significant digit first over the bits
/// that vary (`varying`: the codes' OR xor AND). The first pass, over all keys, scatters each chunk
/// of rebuild()'s in order with the digit counts it took (stable, and the same result for any chunk
/// count); the buckets are then sorted independently, so the threads share them without changing
/// the result.
void LinearBvh::sort_codes(std::uint64_t varying) {
    const std::size_t n = codes_.size();
    codes_tmp_.resize(n);
    order_tmp_.resize(n);
    const int bits = 64 - std::countl_zero(varying);  // bits above are the same in every code
    // The first pass uses the digit that rebuild() counted (bits 52 to 62) when the top bit varies
    // (it does unless the centroids are flat in x); a short or narrow array goes to sort_bucket.
    if (n < 4 * kTopDigits || bits != 63) {
        std::iota(order_.begin(), order_.end(), 0u);
        sort_bucket(codes_.data(), order_.data(), codes_tmp_.data(), order_tmp_.data(), n, bits);
        return;
    }
    constexpr int shift = 63 - kTopBits;
    const std::size_t chunks = histograms_.size() / kTopDigits;
    const std::size_t chunk_len = (n + chunks - 1) / chunks;
    const std::uint64_t* src_k = codes_.data();
    std::uint64_t* dst_k = codes_tmp_.data();
    std::uint32_t* dst_v = order_tmp_.data();
    bucket_start_.resize(kTopDigits + 1);
    std::uint32_t sum = 0;
    for (std::uint32_t d = 0; d < kTopDigits; ++d) {
        bucket_start_[d] = sum;
        for (std::size_t c = 0; c < chunks; ++c) {
            std::uint32_t& h = histograms_[c * kTopDigits + d];
            const std::uint32_t count = h;
            h = sum;
            sum += count;
        }
    }
    bucket_start_[kTopDigits] = sum;
    parallel(chunks, 1, [&](std::size_t c0, std::size_t c1) {
        for (std::size_t c = c0; c < c1; ++c) {
            std::uint32_t* h = histograms_.data() + c * kTopDigits;
            const std::size_t b = std::min(n, c * chunk_len), e = std::min(n, b + chunk_len);
            for (std::size_t i = b; i < e; ++i) {
                const std::uint32_t at = h[src_k[i] >> shift]++;
                dst_k[at] = src_k[i];
                dst_v[at] = std::uint32_t(i);
            }
        }
    });
    // The buckets, in the scattered copy, with the first arrays as their scratch.
    parallel(kTopDigits, 16, [&](std::size_t d0, std::size_t d1) {
        for (std::size_t d = d0; d < d1; ++d) {
            const std::uint32_t b = bucket_start_[d], e = bucket_start_[d + 1];
            if (e - b > 1) sort_bucket(dst_k + b, dst_v + b, codes_.data() + b, order_.data() + b, e - b, shift);
        }
    });
    codes_.swap(codes_tmp_);
    order_.swap(order_tmp_);
}

/// The centroid bounds for resort(), trimmed: the last ones when no change could have moved them
/// (see insert()), else a pass in slot order (a sequential read). Stores the full bounds.
Aabb LinearBvh::resort_bounds(std::size_t chunks) {
    const std::size_t n = objects_.size();
    const Aabb* boxes = objects_.layout().all().data();
    const std::size_t chunk_len = (n + chunks - 1) / chunks;
    std::array<Aabb, kMaxChunks> part;
    if (!centroids_moved_) {
        part[0] = centroid_bounds_;
        for (std::size_t c = 1; c < chunks; ++c) part[c] = Aabb::empty();
    } else
        parallel(chunks, 1, [&](std::size_t c0, std::size_t c1) {
            for (std::size_t c = c0; c < c1; ++c) {
                Vec3 lo = Aabb::empty().min, hi = Aabb::empty().max;
                const std::size_t e = std::min(n, (c + 1) * chunk_len);
                for (std::size_t i = std::min(n, c * chunk_len); i < e; ++i) {
                    const Vec3 m = boxes[i].center();
                    lo = rcb::min(lo, m), hi = rcb::max(hi, m);
                }
                part[c] = {lo, hi};
            }
        });
    Aabb cb = Aabb::empty();
    for (std::size_t c = 0; c < chunks; ++c) cb = merge(cb, part[c]);
    centroid_bounds_ = cb;
    if (params_.outlier_guard) trim_outliers(cb);
    return cb;
}

/// resort()'s step 1: codes and the leaf records (box and uid), in the last order (order_). The
/// records go to the node array's first n nodes (the inner nodes' part, unused until the tree
/// step, and the first leaf, whose record the merge sets aside before it writes that node).
void LinearBvh::resort_codes(std::size_t chunks, const Aabb& cb) {
    const std::size_t n = objects_.size(), chunk_len = (n + chunks - 1) / chunks;
    const Aabb* boxes = objects_.layout().all().data();
    const Uid* uids = objects_.uids().data();
    const std::uint32_t* seq = order_.data();
    std::uint64_t* codes = codes_.data();
    Node* nodes = nodes_.data();
    const MortonGrid grid(cb);
    // The grid by value: read through a reference, the stores to the nodes (boxes too) could
    // alias its bounds and reload them per object (a quarter slower).
    parallel(chunks, 1, [&, grid](std::size_t c0, std::size_t c1) {
        constexpr std::size_t kAhead = 48;  // rows ahead: the gather waits on memory misses
        for (std::size_t c = c0; c < c1; ++c) {
            const std::size_t b = std::min(n, c * chunk_len), e = std::min(n, b + chunk_len);
            for (std::size_t k = b; k < e; ++k) {
                if (k + kAhead < e) {
                    const std::uint32_t ahead = seq[k + kAhead];
                    __builtin_prefetch(&boxes[ahead]);
                    __builtin_prefetch(reinterpret_cast<const char*>(&boxes[ahead + 1]) - 1);
                    __builtin_prefetch(&uids[ahead]);
                }
                const std::uint32_t slot = seq[k];
                const Aabb box = boxes[slot];
                codes[k] = grid.code(box.center());
                nodes[k] = Node{box, {uids[slot], kNullNode}};
            }
        }
    });
}

/// resort()'s steps 2 and 3 over the codes and records of step 1 (position k: the k-th object of
/// the last order): the split of the keys out of order, their sort, the merge of both into
/// codes_tmp_, order_tmp_ and the leaves, and the count of tied codes.
struct LinearBvh::Resort {
    using Span = std::array<std::uint32_t, 2>;
    LinearBvh& t;
    const std::size_t n, chunks, chunk_len;
    const std::uint64_t* codes;
    const std::uint32_t* seq;
    Node* nodes;
    // The first leaf's record, set aside: the merge writes that node.
    const Node last_record;
    // Per chunk: its kept positions in kept_ (after plan(): per part, compacted).
    std::array<Span, kMaxChunks> run;
    // Per part of the merge: outliers [lo, hi), output start.
    std::array<std::array<std::uint32_t, 3>, kMaxChunks> merge_part;
    std::size_t parts = 0;
    // Per part: its keys in runs of equal codes, as far as it sees.
    std::array<std::size_t, kMaxChunks> tied;

    Resort(LinearBvh& tree, std::size_t chunk_count)
        : t(tree),
          n(tree.objects_.size()),
          chunks(chunk_count),
          chunk_len((n + chunk_count - 1) / chunk_count),
          codes(tree.codes_.data()),
          seq(tree.order_.data()),
          nodes(tree.nodes_.data()),
          last_record(tree.nodes_[n - 1]) {}

    const Node& record(std::uint32_t k) const { return k == n - 1 ? last_record : nodes[k]; }
    /// The key is the final order's: the code, then for equal codes the half area's bits and the
    /// slot ("Equal codes" in docs/structures.md, Linear BVH).
    bool less(std::uint32_t i, std::uint32_t j) const {
        if (codes[i] != codes[j]) return codes[i] < codes[j];
        const auto ai = std::bit_cast<std::uint32_t>(record(i).box.half_area()),
                   aj = std::bit_cast<std::uint32_t>(record(j).box.half_area());
        return ai < aj || (ai == aj && seq[i] < seq[j]);
    }
    auto key_less() const {
        return [this](std::uint32_t i, std::uint32_t j) { return less(i, j); };
    }

    /// Step 2, per chunk: kept_[b, top) holds the chunk's kept positions (their keys ascending),
    /// outliers_[c] the others.
    void split_off() {
        constexpr std::uint32_t kLook = 8;
        std::uint32_t* kept = t.kept_.data();
        t.outliers_.resize(chunks);
        t.parallel(chunks, 1, [&](std::size_t c0, std::size_t c1) {
            for (std::size_t c = c0; c < c1; ++c) {
                std::vector<std::uint32_t>& out = t.outliers_[c];
                out.clear();
                const auto b = std::uint32_t(std::min(n, c * chunk_len)), e = std::uint32_t(std::min(n, b + chunk_len));
                std::uint32_t top = b;
                for (std::uint32_t k = b; k < e; ++k) {
                    if (top == b || !less(k, kept[top - 1])) {
                        kept[top++] = k;
                        continue;
                    }
                    // kept[p, top) are the kept keys above k's, looked for down to kLook of them.
                    std::uint32_t p = top - 1;
                    while (p > b && top - p < kLook && less(k, kept[p - 1])) --p;
                    if (p == b || !less(k, kept[p - 1])) {
                        out.insert(out.end(), kept + p, kept + top);
                        top = p;
                        kept[top++] = k;
                    } else {
                        out.push_back(k);
                    }
                }
                run[c] = {b, top};
            }
        });
    }

    /// Where two chunks' kept runs meet out of order, the same rule on one side or the other.
    void join_runs() {
        const std::uint32_t* kept = t.kept_.data();
        std::vector<std::uint32_t>& extra = t.outliers_[0];
        std::size_t prev = chunks;  // the last chunk with kept keys so far
        for (std::size_t c = 0; c < chunks; ++c) {
            std::uint32_t &kb = run[c][0], &kt = run[c][1];
            while (kb < kt && prev < chunks && less(kept[kb], kept[run[prev][1] - 1])) {
                std::uint32_t &pb = run[prev][0], &pt = run[prev][1];
                if (pt - pb >= 2 && !less(kept[kb], kept[pt - 2]))
                    extra.push_back(kept[--pt]);
                else
                    extra.push_back(kept[kb++]);
                if (pb == pt) {  // that run emptied: compare with the one before it
                    std::size_t q = prev;
                    prev = chunks;
                    while (q-- > 0)
                        if (run[q][0] < run[q][1]) {
                            prev = q;
                            break;
                        }
                }
            }
            if (kb < kt) prev = c;
        }
    }

    /// All the outliers, sorted; false when they are too many (the radix path then).
    bool sort_outliers() {
        std::vector<std::uint32_t>& out = t.outliers_all_;
        out.clear();
        for (std::size_t c = 0; c < chunks; ++c) out.insert(out.end(), t.outliers_[c].begin(), t.outliers_[c].end());
        if (out.size() > n / 16) return false;  // too far from the last order: the radix path
        std::sort(out.begin(), out.end(), key_less());
        return true;
    }

    /// Step 3's parts, one per chunk with kept keys: its run and the outliers from its first kept
    /// key (from the start for the first such chunk) to the next chunk's first kept key. False
    /// when no chunk kept a key.
    bool plan() {
        const std::vector<std::uint32_t>& out = t.outliers_all_;
        const std::uint32_t* kept = t.kept_.data();
        std::uint32_t written = 0, lo = 0;
        std::array<std::size_t, kMaxChunks> chunk_of;
        parts = 0;
        for (std::size_t c = 0; c < chunks; ++c)
            if (run[c][0] < run[c][1]) chunk_of[parts++] = c;
        for (std::size_t i = 0; i < parts; ++i) {
            const std::size_t c = chunk_of[i];
            const std::uint32_t hi = i + 1 < parts
                                         ? std::uint32_t(std::lower_bound(out.begin(), out.end(),
                                                                          kept[run[chunk_of[i + 1]][0]], key_less()) -
                                                         out.begin())
                                         : std::uint32_t(out.size());
            merge_part[i] = {lo, hi, written + lo};
            written += run[c][1] - run[c][0];
            lo = hi;
            run[i] = run[c];  // compacted: part i's kept run
        }
        return parts != 0;
    }

    /// Step 3, the merge per part into codes_tmp_, order_tmp_ and the leaves. Each part also counts
    /// its keys in runs of equal codes (the stats' "tied_codes", already in their order) as far as
    /// it sees; count_tied() settles the parts' first and last keys.
    void merge() {
        const std::uint32_t leaf_base = t.leaf_base_;
        std::uint64_t* out_codes = t.codes_tmp_.data();
        std::uint32_t* out_order = t.order_tmp_.data();
        const std::uint32_t* outl = t.outliers_all_.data();
        const std::uint32_t* kept = t.kept_.data();
        t.parallel(parts, 1, [&](std::size_t i0, std::size_t i1) {
            // Local restrict pointers: the stores below then do not make the loop reload them.
            const std::uint64_t* __restrict in_codes = codes;
            const std::uint32_t* __restrict in_order = seq;
            const std::uint32_t* __restrict kept_at = kept;
            std::uint64_t* __restrict codes_to = out_codes;
            std::uint32_t* __restrict order_to = out_order;
            Node* __restrict leaves = nodes + leaf_base;
            for (std::size_t i = i0; i < i1; ++i) {
                std::uint32_t a = run[i][0];
                const std::uint32_t a_end = run[i][1];
                std::uint32_t o = merge_part[i][0];
                const std::uint32_t o_end = merge_part[i][1];
                const std::uint32_t j0 = merge_part[i][2];
                std::uint32_t j = j0;
                std::size_t same_count = 0, same = 0;  // same: keys so far with the previous key's code
                std::uint64_t prev = 0;
                auto put = [&](std::uint32_t k) {
                    const std::uint64_t code = in_codes[k];
                    same = j != j0 && code == prev ? same + 1 : 1;
                    same_count += same == 2 ? 2 : same > 2;
                    prev = code;
                    codes_to[j] = code;
                    order_to[j] = in_order[k];
                    leaves[j] = k == n - 1 ? last_record : nodes[k];
                    ++j;
                };
                for (;;) {
                    // The kept keys below the next outlier (all, when none is left): found by a
                    // binary search, then copied with no comparison per key.
                    const std::uint32_t stop =
                        o < o_end ? std::uint32_t(std::lower_bound(kept_at + a, kept_at + a_end, outl[o], key_less()) -
                                                  kept_at)
                                  : a_end;
                    for (; a < stop; ++a) put(kept_at[a]);
                    if (o == o_end) break;
                    put(outl[o++]);
                }
                tied[i] = same_count;
            }
        });
    }

    /// The tied codes of the merged keys (codes_ after the swap): the parts' counts, with the keys
    /// at their ends settled against their neighbours across the parts' borders.
    std::size_t count_tied() const {
        const std::uint64_t* c = t.codes_.data();
        // Whether key j has an equal code beside it in [b, e).
        auto in_run = [c](std::size_t j, std::size_t b, std::size_t e) {
            return (j > b && c[j] == c[j - 1]) || (j + 1 < e && c[j] == c[j + 1]);
        };
        std::size_t total = 0;
        for (std::size_t i = 0; i < parts; ++i) {
            const std::size_t b = merge_part[i][2], e = i + 1 < parts ? merge_part[i + 1][2] : n;
            total += tied[i];
            for (std::size_t j : {b, e - 1}) {
                total += std::size_t(in_run(j, 0, n)) - std::size_t(in_run(j, b, e));
                if (e - b == 1) break;
            }
        }
        return total;
    }
};

/// Steps 1 and 2 (codes, sort, equal codes) and the leaves, from the last rebuild's order instead
/// of a radix sort, when at most 1/16 of the objects changed since: the objects, visited in the
/// last sorted order (its slots; slots gone dropped, new ones last), are then nearly in order, as
/// in the incremental sorts of sweep-and-prune broad phases (Baraff 1992; Cohen et al. 1995,
/// "I-COLLIDE"). One pass gathers each box and uid in that order, codes it and writes its leaf
/// record; one pass splits off the keys (code, then half area and slot) that break the order (the
/// kept keys above the new one are dropped when at most kLook of them are, else the new one), the
/// dropped ones are sorted, and a merge writes the codes, slots and leaves in order. The result is
/// the radix sort's exactly (same keys, same total order), only cheaper: no scatter over 2048
/// buckets, and the leaves come from records read in order rather than from a gather in sorted
/// order. Returns false (and leaves everything to the radix path) when there is no usable order or
/// more than 1/16 of the keys are out of place (the first build, mass changes, a change of the
/// code bounds that reorders many codes).
template <class Lap>
bool LinearBvh::resort(std::size_t chunks, Lap& lap, bool& bounds_known) {
    const std::size_t n = objects_.size(), n_old = order_.size();
    if (!params_.coherent_sort || n < 4 * kTopDigits || n_old == 0 || changes_ > n / 16) return false;
    // When the bounds changed (an extreme object moved), every code moves on the grid and the
    // Morton order of shifted or scaled points differs from the last one almost everywhere, so the
    // radix path takes over, with these bounds.
    const Aabb cb = resort_bounds(chunks);
    bounds_known = true;
    if (!(cb == code_bounds_)) {
        code_bounds_ = cb;
        return false;
    }
    // The last order: slots past the end dropped (their objects now live in lower slots, which
    // stay where they were: out of place, to be split off), new slots appended.
    if (n < n_old)
        order_.erase(std::remove_if(order_.begin(), order_.end(), [n](std::uint32_t s) { return s >= n; }),
                     order_.end());
    for (std::size_t s = n_old; s < n; ++s) order_.push_back(std::uint32_t(s));
    codes_.resize(n);
    codes_tmp_.resize(n);
    order_tmp_.resize(n);
    kept_.resize(n);
    nodes_.resize(2 * n - 1);
    leaf_base_ = std::uint32_t(n - 1);
    resort_codes(chunks, cb);
    writes_ += n;  // the leaf records, staged in the inner nodes' part
    lap(phases_.codes);
    Resort r(*this, chunks);
    r.split_off();
    r.join_runs();
    if (!r.sort_outliers() || !r.plan()) return false;
    r.merge();
    update_work_ += outliers_all_.size();
    codes_.swap(codes_tmp_);
    order_.swap(order_tmp_);
    tied_codes_ = r.count_tied();
    lap(phases_.sort);
    return true;
}

/// Step 1 of the radix path: Morton codes of the centroids in the bounds of the centroids (min and
/// max are exact, so the chunking does not change them). One pass finds the bounds and, in the
/// same read of the boxes, codes them in the last rebuild's bounds; only when the bounds changed
/// (an extreme object moved) does a second pass code them again. The same pass counts the codes'
/// top digit for the sort. Returns the bits that vary among the codes (their OR xor AND).
std::uint64_t LinearBvh::encode(std::size_t chunks, bool bounds_known) {
    const std::size_t n = objects_.size(), chunk_len = (n + chunks - 1) / chunks;
    const Aabb* boxes = objects_.layout().all().data();
    struct Part {
        Vec3 min, max;
        std::uint64_t all_or, all_and;
    };
    std::array<Part, kMaxChunks> part;
    codes_.resize(n);
    order_.resize(n);
    histograms_.resize(chunks * kTopDigits);
    auto pass = [&](const Aabb& cb, bool bounds, bool codes) {
        const MortonGrid grid(cb);
        parallel(chunks, 1, [&, grid](std::size_t c0, std::size_t c1) {  // by value, as in resort_codes()
            for (std::size_t c = c0; c < c1; ++c) {
                std::uint32_t* h = histograms_.data() + c * kTopDigits;
                std::fill_n(h, kTopDigits, 0u);
                Vec3 lo = Aabb::empty().min, hi = Aabb::empty().max;
                std::uint64_t all_or = 0, all_and = ~0ull;
                const std::size_t e = std::min(n, (c + 1) * chunk_len);
                for (std::size_t i = c * chunk_len; i < e; ++i) {
                    const Vec3 m = boxes[i].center();
                    if (bounds) lo = rcb::min(lo, m), hi = rcb::max(hi, m);
                    if (!codes) continue;
                    const std::uint64_t code = grid.code(m);
                    codes_[i] = code;
                    all_or |= code, all_and &= code;
                    ++h[code >> (63 - kTopBits)];
                }
                if (bounds) part[c].min = lo, part[c].max = hi;
                part[c].all_or = all_or, part[c].all_and = all_and;
            }
        });
    };
    if (bounds_known) {  // resort() found them: one pass
        pass(code_bounds_, false, true);
    } else {
        pass(code_bounds_, true, !code_bounds_.is_empty());
        Aabb cb = Aabb::empty();
        for (std::size_t c = 0; c < chunks; ++c) cb = merge(cb, Aabb{part[c].min, part[c].max});
        centroid_bounds_ = cb;
        if (params_.outlier_guard) trim_outliers(cb);
        if (code_bounds_.is_empty() || !(cb == code_bounds_)) {
            code_bounds_ = cb;
            pass(cb, false, true);
        }
    }
    std::uint64_t all_or = 0, all_and = ~0ull;
    for (std::size_t c = 0; c < chunks; ++c) all_or |= part[c].all_or, all_and &= part[c].all_and;
    return all_or ^ all_and;
}

void LinearBvh::rebuild() {
    dirty_ = false;
    const std::size_t n = objects_.size();
    // Crowds are looked for while the last tree had some, else every kCrowdCheckEvery rebuilds.
    crowds_checked_ = params_.crowd_guard && (crowds_ > 0 || ++rebuilds_since_crowd_check_ >= kCrowdCheckEvery);
    if (crowds_checked_) rebuilds_since_crowd_check_ = 0;
    crowds_ = tied_codes_ = 0;
    if (n == 0) {
        nodes_.clear();
        meta_.clear();
        codes_.clear();
        order_.clear();
        common_.clear();
        ranges_.clear();
        leaf_base_ = 0;
        return;
    }
    using Clock = std::chrono::steady_clock;
    auto lap = [last = Clock::now()](double& ms) mutable {
        const Clock::time_point now = Clock::now();
        ms = std::chrono::duration<double, std::milli>(now - last).count();
        last = now;
    };
    phases_ = {};
    const std::size_t chunks = arena_ ? std::size_t(params_.threads) * kChunksPerThread : 1;
    // Steps 1 and 2 from the last tree's order when few objects changed (see resort()); it writes
    // the leaves too. Otherwise, or when it finds the order too far from the new one:
    bool bounds_known = false;
    const bool leaves_written = resorted_ = resort(chunks, lap, bounds_known);
    if (!leaves_written) {
        const std::uint64_t varying = encode(chunks, bounds_known);  // 1. Morton codes
        lap(phases_.codes);
        // 2. Sort; equal codes by size ("Equal codes" in docs/structures.md, Linear BVH).
        sort_codes(varying);
        update_work_ += n;
        order_equal_codes(chunks);
        lap(phases_.sort);
    }
    writes_ += n;  // the sorted codes (by the merge or the sort)
    changes_ = 0;
    centroids_moved_ = false;
    nodes_.resize(2 * n - 1);
    leaf_base_ = std::uint32_t(n - 1);
    if (n == 1) {
        nodes_[0] = Node{objects_.layout().all()[0], {objects_.uid(0), kNullNode}};
        ++writes_;
        meta_.clear();
        common_.clear();
        ranges_.clear();
        lap(phases_.tree);
        return;
    }
    build_tree(chunks, leaves_written);
    writes_ += 2 * n - 1;  // n leaves (here or by the merge) and n − 1 inner nodes
    lap(phases_.tree);
}

/// Step 3's climb from a finished node of the radix tree (see build_tree()): the arrays it writes,
/// as plain pointers, so that stores into the nodes cannot alias what the loop reads.
struct LinearBvh::Climb {
    const std::uint64_t* codes;
    std::uint32_t last;  // the last key
    Node* nodes;
    Meta* meta;
    std::uint32_t* bound;
    std::array<std::uint32_t, 2>* ranges;
    Aabb* common;
    std::uint32_t leaf_base;
    bool check_crowds;

    /// δ(s): the common prefix of the keys s and s + 1; equal codes compare their indices instead
    /// (Karras 2012, §4: the keys are in effect code·2^32 + index).
    int delta(std::uint32_t s) const {
        const std::uint64_t x = codes[s] ^ codes[s + 1];
        return x ? std::countl_zero(x) : 64 + std::countl_zero(s ^ (s + 1));
    }

    /// Climbs from the finished node [first, end] within the chunk [b, e); returns whether it
    /// stopped at the chunk's edge (the sibling starts outside; [first, end] is then that node).
    /// Adds the crowds it marks to `found`. The common box of a node: the intersection of the
    /// boxes below, kept only while it is not empty (kShared); once empty it stays empty further
    /// up, so most nodes of a scene without crowds never compute one.
    __attribute__((always_inline)) bool operator()(std::uint32_t& first, std::uint32_t& end, std::uint32_t b,
                                                   std::uint32_t e, std::size_t& found) const {
        std::uint32_t l = first, r = end;
        bool left = l == 0 || (r != last && delta(r) > delta(l - 1));
        while (l != 0 || r != last) {
            if (left ? r + 1 == e : l == b) {
                first = l, end = r;
                return true;
            }
            const std::uint32_t split = left ? r : l - 1;
            const std::uint32_t other = bound[split];
            if (other == kNullNode) {
                bound[split] = left ? l : r;
                return false;
            }
            bound[split] = kNullNode;
            if (left)
                r = other;
            else
                l = other;
            const bool root = l == 0 && r == last;
            left = !root && (l == 0 || (r != last && delta(r) > delta(l - 1)));
            const std::uint32_t p = root ? 0 : left ? r : l;
            // A leaf child's Meta is implied (height 0, shared); meta[split] is read either way
            // (always in range) so that the choice is a select, not a branch.
            const bool leaf0 = l == split, leaf1 = r == split + 1;
            const std::uint32_t c0 = leaf0 ? leaf_base + split : split;
            const std::uint32_t c1 = leaf1 ? leaf_base + split + 1 : split + 1;
            const Meta m0 = leaf0 ? Meta{0, kShared} : meta[split];
            const Meta m1 = leaf1 ? Meta{0, kShared} : meta[std::min(split + 1, last - 1)];
            const Node& a = nodes[c0];
            const Node& c = nodes[c1];
            Node& node = nodes[p];
            node.box = merge(a.box, c.box);
            node.child[0] = c0, node.child[1] = c1;
            Meta m{std::uint8_t(1 + std::max(m0.height, m1.height)), 0};
            if (check_crowds && (m0.flags & m1.flags & kShared)) {
                const Aabb& ca = leaf0 ? a.box : common[c0];
                const Aabb& cc = leaf1 ? c.box : common[c1];
                const Aabb shared{rcb::max(ca.min, cc.min), rcb::min(ca.max, cc.max)};
                if (shared.min.x <= shared.max.x && shared.min.y <= shared.max.y && shared.min.z <= shared.max.z) {
                    common[p] = shared;
                    m.flags = kShared;
                    if (r - l + 1 >= kCrowdLeaves) {
                        m.flags |= kCrowd;
                        ranges[p] = {l, r};
                        ++found;
                    }
                }
            }
            meta[p] = m;
        }
        return false;
    }
};

/// 3. The leaves (unless resort() wrote them) and the binary radix tree of Karras 2012 (thesis
/// Algorithm 3) with its bounds (thesis Algorithm 4) in one bottom-up pass, as Apetrei 2014 ("Fast
/// and simple agglomerative LBVH construction") builds it: a node over the keys [l, r] hangs below
/// the split at r (as the left child) when its keys share more bits with key r + 1 than key l − 1
/// does, else below the split at l − 1 (as the right child). Each leaf climbs; at each split the
/// first climber to arrive leaves its far end in bound_ and stops, the second learns the parent's
/// range from it, merges the children and goes on. The nodes keep Karras' numbering (a node at the
/// end of its range where its parent splits; root 0), so the tree is exactly the one Algorithm 3
/// gives: each node is merged once, from its finished children. Threads take chunks of the leaves
/// and climb only while the sibling starts in their chunk (then every split and node they touch is
/// their own: no atomics); the few nodes stopped at a chunk's edge climb on afterwards, on one
/// thread. The tree is the same for any chunking.
void LinearBvh::build_tree(std::size_t chunks, bool leaves_written) {
    const std::size_t n = objects_.size(), chunk_len = (n + chunks - 1) / chunks;
    meta_.resize(n - 1);
    common_.resize(n - 1);
    ranges_.resize(n - 1);
    bound_.resize(n - 1, kNullNode);
    Node* nodes = nodes_.data();
    const std::uint32_t leaf_base = leaf_base_;
    const Climb climb{codes_.data(),  std::uint32_t(n - 1), nodes,     meta_.data(),   bound_.data(),
                      ranges_.data(), common_.data(),       leaf_base, crowds_checked_};
    const Aabb* boxes = objects_.layout().all().data();
    const Uid* uids = objects_.uids().data();
    const std::uint32_t* order = order_.data();
    pending_.resize(chunks);
    constexpr std::uint32_t kAhead = 16, kBlock = 512;
    std::array<std::size_t, kMaxChunks> found{};
    parallel(chunks, 1, [&](std::size_t c0, std::size_t c1) {
        for (std::size_t c = c0; c < c1; ++c) {
            const std::uint32_t b = std::uint32_t(std::min(n, c * chunk_len)),
                                e = std::uint32_t(std::min(n, b + chunk_len));
            pending_[c].clear();
            // Blocks of leaves: first their boxes and uids, which come in sorted order, scattered
            // over the slots (a tight loop that keeps many loads in flight), then their climbs,
            // which find the new leaves in the cache.
            for (std::uint32_t bb = b; bb < e; bb += kBlock) {
                const std::uint32_t be = std::min(e, bb + kBlock);
                for (std::uint32_t k = bb; k < be && !leaves_written; ++k) {
                    if (k + kAhead < e) {
                        const std::uint32_t ahead = order[k + kAhead];
                        __builtin_prefetch(&boxes[ahead]);
                        __builtin_prefetch(reinterpret_cast<const char*>(&boxes[ahead + 1]) - 1);
                        __builtin_prefetch(&uids[ahead]);
                    }
                    const std::uint32_t slot = order[k];
                    nodes[leaf_base + k] = Node{boxes[slot], {uids[slot], kNullNode}};
                }
                for (std::uint32_t k = bb; k < be; ++k) {
                    // The next block's boxes and uids into L2 while this block climbs (the climbs
                    // wait on branches, not on memory): its gather then hits the cache.
                    if (k + kBlock < e && !leaves_written) {
                        const std::uint32_t next = order[k + kBlock];
                        __builtin_prefetch(&boxes[next], 0, 2);
                        __builtin_prefetch(reinterpret_cast<const char*>(&boxes[next + 1]) - 1, 0, 2);
                        __builtin_prefetch(&uids[next], 0, 2);
                    }
                    std::uint32_t l = k, r = k;
                    if (climb(l, r, b, e, found[c])) pending_[c].push_back({l, r});
                }
            }
        }
    });
    // The nodes stopped at a chunk's edge climb on, with no edge.
    std::size_t crowds = 0;
    for (std::size_t c = 0; c < chunks; ++c) {
        crowds += found[c];
        for (auto [l, r] : pending_[c]) climb(l, r, 0, std::uint32_t(n), crowds);
    }
    crowds_ = crowds;
}

void LinearBvh::order_equal_codes(std::size_t chunks) {
    const std::size_t n = codes_.size(), chunk_len = (n + chunks - 1) / chunks;
    std::array<std::size_t, kMaxChunks> tied{};
    // Each chunk orders the runs that start in it (a run may end in a later chunk): the runs are
    // disjoint, and each sorts its keys in its own part of the scratch, so the chunks share nothing
    // and the order does not depend on the cut.
    parallel(chunks, 1, [&](std::size_t c0, std::size_t c1) {
        for (std::size_t c = c0; c < c1; ++c) {
            const std::size_t cb = std::min(n, c * chunk_len), ce = std::min(n, cb + chunk_len);
            std::size_t b = cb;
            while (b > 0 && b < ce && codes_[b] == codes_[b - 1]) ++b;  // a run from the chunk before
            for (std::size_t e; b < ce; b = e) {
                for (e = b + 1; e < n && codes_[e] == codes_[b];) ++e;
                if (e - b < 2) continue;
                tied[c] += e - b;
                // Keys: the half area's bits (monotone for non-negative floats) above the slot; the
                // slot breaks ties, so the order does not depend on the sort.
                std::uint64_t* keys = codes_tmp_.data() + b;
                for (std::size_t k = b; k < e; ++k) {
                    const std::uint32_t slot = order_[k];
                    keys[k - b] =
                        std::uint64_t(std::bit_cast<std::uint32_t>(objects_.box(slot).half_area())) << 32 | slot;
                }
                std::sort(keys, keys + (e - b));
                for (std::size_t k = b; k < e; ++k) order_[k] = std::uint32_t(keys[k - b]);
            }
        }
    });
    tied_codes_ = 0;
    for (std::size_t c = 0; c < chunks; ++c) tied_codes_ += tied[c];
}

void LinearBvh::trim_outliers(Aabb& cb) {
    // A fixed stride over the slots: deterministic, and O(1) work per rebuild beyond the copy.
    const std::size_t n = objects_.size(), samples = std::min<std::size_t>(n, 4096);
    const std::size_t stride = samples ? n / samples : 1;
    auto centre = [&](std::size_t i, int a) { return objects_.box(i * stride).center()[a]; };
    trimmed_ = rcb::trim_outliers(cb, samples, centre, centre);
}

double LinearBvh::sah_cost() const {
    return rcb::sah_cost(
        root(), [&](std::uint32_t n) -> const Aabb& { return nodes_[n].box; },
        [&](std::uint32_t n, std::vector<std::uint32_t>& stack) {
            if (!is_leaf(n)) stack.push_back(nodes_[n].child[0]), stack.push_back(nodes_[n].child[1]);
        },
        std::uint32_t(nodes_.size()));
}

std::size_t LinearBvh::memory_bytes() const {
    std::size_t outliers = outliers_all_.capacity();
    for (const std::vector<std::uint32_t>& o : outliers_) outliers += o.capacity();
    return nodes_.capacity() * sizeof(Node) + meta_.capacity() * sizeof(Meta) + objects_.memory_bytes() +
           (codes_.capacity() + codes_tmp_.capacity()) * sizeof(std::uint64_t) +
           (order_.capacity() + order_tmp_.capacity() + histograms_.capacity() + bucket_start_.capacity() +
            bound_.capacity() + kept_.capacity() + outliers) *
               sizeof(std::uint32_t) +
           scratch_bytes() + common_.capacity() * sizeof(Aabb) + ranges_.capacity() * sizeof(ranges_[0]) +
           sizeof(*this);
}

nlohmann::json LinearBvh::stats() const {
    return {{"sah_cost", sah_cost()}, {"depth", height()},         {"nodes", nodes_.size()},
            {"crowds", crowds_},      {"tied_codes", tied_codes_}, {"outlier_trimmed", trimmed_}};
}

void LinearBvh::check() const {
    auto fail = [](const std::string& what) { broken_invariant("lbvh", what); };
    if (dirty_) fail("tree not rebuilt after changes (commit missing)");
    const std::size_t n = objects_.size();
    objects_.check("lbvh");
    if (nodes_.size() != (n ? 2 * n - 1 : 0))
        fail("node array has " + std::to_string(nodes_.size()) + " nodes for " + std::to_string(n) + " objects");
    for (std::size_t k = 1; k < codes_.size(); ++k)
        if (codes_[k - 1] > codes_[k]) fail("Morton codes not sorted at " + std::to_string(k));
    if (n == 0) return;
    std::vector<std::uint8_t> seen(nodes_.size(), 0);
    std::vector<std::uint32_t> stack{0};
    if (meta_.size() != n - 1) fail("meta array has " + std::to_string(meta_.size()) + " entries");
    std::size_t leaves = 0;
    std::vector<std::uint8_t> slot_seen(n, 0);
    while (!stack.empty()) {
        const std::uint32_t v = stack.back();
        stack.pop_back();
        if (v >= nodes_.size()) fail("child out of range");
        if (seen[v]++) fail("node " + std::to_string(v) + " reached twice");
        const Node& node = nodes_[v];
        if (is_leaf(v)) {
            ++leaves;
            if (node.child[1] != kNullNode) fail("leaf " + std::to_string(v) + " has a second child");
            const std::uint32_t* slot = objects_.find(node.child[0]);
            if (!slot) fail("leaf " + std::to_string(v) + " holds unknown uid " + std::to_string(node.child[0]));
            if (slot_seen[*slot]++) fail("uid " + std::to_string(node.child[0]) + " in two leaves");
            if (!(objects_.box(*slot) == node.box))
                fail("leaf box of uid " + std::to_string(node.child[0]) + " is stale");
            continue;
        }
        int hmax = -1;
        for (int k = 0; k < 2; ++k) {
            const std::uint32_t c = node.child[k];
            if (c >= nodes_.size()) fail("child out of range");
            if (!node.box.contains(nodes_[c].box))
                fail("node " + std::to_string(v) + " does not enclose child " + std::to_string(c));
            hmax = std::max(hmax, is_leaf(c) ? 0 : int(meta_[c].height));
            stack.push_back(c);
        }
        if (meta_[v].height != 1 + hmax) fail("node " + std::to_string(v) + " has a wrong height");
    }
    if (leaves != n) fail(std::to_string(n) + " objects but " + std::to_string(leaves) + " leaves reached");
    // Crowds: every inner node's leaf range and common box as the subtree gives them, and the flag
    // set exactly where the rule says.
    std::size_t crowds = 0;
    auto check = [&](auto&& self, std::uint32_t v, std::uint32_t& first, std::uint32_t& last, Aabb& common) -> void {
        if (is_leaf(v)) {
            first = last = v - leaf_base_;
            common = nodes_[v].box;
            return;
        }
        std::uint32_t f0, l0, f1, l1;
        Aabb c0, c1;
        self(self, nodes_[v].child[0], f0, l0, c0);
        self(self, nodes_[v].child[1], f1, l1, c1);
        if (l0 + 1 != f1) fail("node " + std::to_string(v) + ": its children's leaves are not consecutive");
        first = f0, last = l1;
        common = {rcb::max(c0.min, c1.min), rcb::min(c0.max, c1.max)};
        const bool shared =
            common.min.x <= common.max.x && common.min.y <= common.max.y && common.min.z <= common.max.z;
        const bool crowd = crowds_checked_ && last - first + 1 >= kCrowdLeaves && shared;
        if (crowd && (ranges_[v][0] != first || ranges_[v][1] != last))
            fail("crowd " + std::to_string(v) + " has a wrong leaf range");
        if (bool(meta_[v].flags & kCrowd) != crowd)
            fail("node " + std::to_string(v) +
                 (crowd ? " is a crowd but not marked" : " is marked as a crowd but is none"));
        if (bool(meta_[v].flags & kShared) != (crowds_checked_ && shared))
            fail("node " + std::to_string(v) + " has a wrong shared flag");
        if ((meta_[v].flags & kShared) && !(common_[v] == common))
            fail("node " + std::to_string(v) + " has a stale common box");
        crowds += crowd;
    };
    std::uint32_t first, last;
    Aabb common;
    check(check, 0, first, last, common);
    if (first != 0 || last != n - 1) fail("the root does not span every leaf");
    if (crowds != crowds_) fail("crowd count " + std::to_string(crowds_) + ", tree has " + std::to_string(crowds));
}

}  // namespace rcb
