#include "core/structures/linear_bvh.h"

#include <algorithm>
#include <bit>
#include <chrono>
#include <stdexcept>
#include <string>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "core/structures/common/outlier_trim.h"

namespace rcb {

struct LinearBvh::Arena {
    explicit Arena(int threads) : arena(threads) {}
    tbb::task_arena arena;
};

namespace {

/// Spreads the low 21 bits of v to every third bit (the classic magic-number interleave).
std::uint64_t spread_bits(std::uint64_t v) {
    v &= 0x1fffffu;
    v = (v | v << 32) & 0x1f00000000ffffull;
    v = (v | v << 16) & 0x1f0000ff0000ffull;
    v = (v | v << 8) & 0x100f00f00f00f00full;
    v = (v | v << 4) & 0x10c30c30c30c30c3ull;
    v = (v | v << 2) & 0x1249249249249249ull;
    return v;
}

constexpr int kDigitBits = 11;
constexpr std::uint32_t kDigits = 1u << kDigitBits;
constexpr int kPasses = (63 + kDigitBits - 1) / kDigitBits;  // 6

}  // namespace

LinearBvh::LinearBvh() : LinearBvh(Params{}) {}

LinearBvh::LinearBvh(const Params& p) : params_(p) {
    if (params_.threads > 1) arena_ = std::make_unique<Arena>(params_.threads);
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
    rebuilds_since_crowd_check_ = kCrowdCheckEvery;  // look for crowds in the first tree
    rebuild();
}

void LinearBvh::insert(const Object& o) {
    objects_.insert(o);
    dirty_ = true;
}

void LinearBvh::remove(Uid uid) {
    objects_.remove(uid);
    dirty_ = true;
}

void LinearBvh::move(const Object& o) {
    objects_.move(o);
    dirty_ = true;
}

void LinearBvh::commit() {
    if (dirty_) rebuild();
}

/// Stable LSD radix sort of codes_ with order_ as payload. Per pass each chunk of the input counts
/// its digits, an exclusive scan over (digit, chunk) gives every chunk its output offsets, and each
/// chunk scatters its own range in order: stable, and the same result for any chunk count.
void LinearBvh::radix_sort() {
    const std::size_t n = codes_.size();
    const std::size_t chunks = arena_ && n >= 65536 ? std::size_t(params_.threads) * 4 : 1;
    const std::size_t chunk_len = (n + chunks - 1) / chunks;
    histograms_.assign(chunks * kDigits, 0);
    codes_tmp_.resize(n);
    order_tmp_.resize(n);
    std::uint64_t* src_k = codes_.data();
    std::uint64_t* dst_k = codes_tmp_.data();
    std::uint32_t* src_v = order_.data();
    std::uint32_t* dst_v = order_tmp_.data();
    // Bits in which the codes differ at all: passes over constant digits are skipped.
    std::uint64_t all_or = 0, all_and = ~0ull;
    for (std::size_t i = 0; i < n; ++i) all_or |= src_k[i], all_and &= src_k[i];
    const std::uint64_t varying = all_or ^ all_and;
    // One chunk: the digit counts of every pass in a single read (they do not depend on the order).
    std::vector<std::uint32_t>& all_counts = all_counts_;
    if (chunks == 1) {
        all_counts.assign(std::size_t(kPasses) * kDigits, 0u);
        for (std::size_t i = 0; i < n; ++i)
            for (int pass = 0; pass < kPasses; ++pass)
                ++all_counts[std::size_t(pass) * kDigits + ((src_k[i] >> (pass * kDigitBits)) & (kDigits - 1))];
    }
    for (int pass = 0; pass < kPasses; ++pass) {
        const int shift = pass * kDigitBits;
        if (((varying >> shift) & (kDigits - 1)) == 0) continue;
        if (chunks == 1)
            std::copy_n(all_counts.begin() + std::ptrdiff_t(pass) * kDigits, kDigits, histograms_.begin());
        else
            std::fill(histograms_.begin(), histograms_.end(), 0u);
        if (chunks > 1)
            parallel(chunks, 1, [&](std::size_t c0, std::size_t c1) {
                for (std::size_t c = c0; c < c1; ++c) {
                    std::uint32_t* h = histograms_.data() + c * kDigits;
                    const std::size_t b = std::min(n, c * chunk_len), e = std::min(n, b + chunk_len);
                    for (std::size_t i = b; i < e; ++i) ++h[(src_k[i] >> shift) & (kDigits - 1)];
                }
            });
        std::uint32_t sum = 0;
        for (std::uint32_t d = 0; d < kDigits; ++d)
            for (std::size_t c = 0; c < chunks; ++c) {
                std::uint32_t& h = histograms_[c * kDigits + d];
                const std::uint32_t count = h;
                h = sum;
                sum += count;
            }
        parallel(chunks, 1, [&](std::size_t c0, std::size_t c1) {
            for (std::size_t c = c0; c < c1; ++c) {
                std::uint32_t* h = histograms_.data() + c * kDigits;
                const std::size_t b = std::min(n, c * chunk_len), e = std::min(n, b + chunk_len);
                for (std::size_t i = b; i < e; ++i) {
                    const std::uint32_t at = h[(src_k[i] >> shift) & (kDigits - 1)]++;
                    dst_k[at] = src_k[i];
                    dst_v[at] = src_v[i];
                }
            }
        });
        std::swap(src_k, dst_k);
        std::swap(src_v, dst_v);
    }
    if (src_k != codes_.data()) {
        codes_.swap(codes_tmp_);
        order_.swap(order_tmp_);
    }
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
        codes_.clear();
        order_.clear();
        common_.clear();
        ranges_.clear();
        leaf_base_ = 0;
        stack_.assign(1, 0);
        return;
    }
    constexpr std::size_t kGrain = 4096;
    using Clock = std::chrono::steady_clock;
    auto lap = [last = Clock::now()](double& ms) mutable {
        const Clock::time_point now = Clock::now();
        ms = std::chrono::duration<double, std::milli>(now - last).count();
        last = now;
    };
    phases_ = {};
    // 1. Morton codes of the centroids in the bounds of the centroids (min and max are exact, so
    //    the chunking does not change them).
    const std::size_t chunks = arena_ ? std::size_t(params_.threads) * 4 : 1;
    std::vector<Aabb> part(chunks, Aabb::empty());
    const std::size_t chunk_len = (n + chunks - 1) / chunks;
    parallel(chunks, 1, [&](std::size_t c0, std::size_t c1) {
        for (std::size_t c = c0; c < c1; ++c) {
            Aabb b = Aabb::empty();
            const std::size_t e = std::min(n, (c + 1) * chunk_len);
            for (std::size_t i = c * chunk_len; i < e; ++i) {
                const Vec3 m = objects_.box(i).center();
                b.min = rcb::min(b.min, m), b.max = rcb::max(b.max, m);
            }
            part[c] = b;
        }
    });
    Aabb cb = Aabb::empty();
    for (const Aabb& b : part) cb = merge(cb, b);
    if (params_.outlier_guard) trim_outliers(cb);
    Vec3 scale;
    constexpr float kMax = float((1u << 21) - 1);
    for (int a = 0; a < 3; ++a) {
        const float ext = cb.max[a] - cb.min[a];
        scale[a] = ext > 0 ? kMax / ext : 0.0f;
    }
    codes_.resize(n);
    order_.resize(n);
    parallel(n, kGrain, [&](std::size_t b, std::size_t e) {
        for (std::size_t i = b; i < e; ++i) {
            const Vec3 c = objects_.box(i).center();
            std::uint64_t q[3];
            for (int a = 0; a < 3; ++a) {
                const float v = std::clamp((c[a] - cb.min[a]) * scale[a], 0.0f, kMax);
                q[a] = std::uint64_t(v);
            }
            codes_[i] = spread_bits(q[0]) << 2 | spread_bits(q[1]) << 1 | spread_bits(q[2]);
            order_[i] = std::uint32_t(i);
        }
    });
    lap(phases_.codes);
    // 2. Sort; equal codes by size (see "Equal codes" in the header).
    radix_sort();
    order_equal_codes();
    lap(phases_.sort);
    // Leaves in sorted order.
    nodes_.resize(2 * n - 1);
    leaf_base_ = std::uint32_t(n - 1);
    parallel(n, kGrain, [&](std::size_t b, std::size_t e) {
        for (std::size_t k = b; k < e; ++k) {
            if (k + 16 < e)
                __builtin_prefetch(&objects_.layout().all()[order_[k + 16]]),
                    __builtin_prefetch(&objects_.uids()[order_[k + 16]]);
            const std::uint32_t slot = order_[k];
            nodes_[leaf_base_ + k] = Node{objects_.box(slot), {objects_.uid(slot), kNullNode}, kNullNode, 0, kShared};
        }
    });
    lap(phases_.leaves);
    if (n > 1) {
        common_.resize(n - 1);
        ranges_.resize(n - 1);
        // 3. Karras Algorithm 3: every inner node i finds its range [i, j] and split γ on its own.
        const std::uint64_t* codes = codes_.data();
        const std::int64_t count = std::int64_t(n);
        parallel(n - 1, kGrain, [&](std::size_t b, std::size_t e) {
            for (std::size_t ui = b; ui < e; ++ui) {
                const std::int64_t i = std::int64_t(ui);
                const std::uint64_t ci = codes[ui];
                // Karras 2012 δ(i, j): the length of the common prefix of the sorted keys i and j,
                // −1 outside the array; equal codes compare their indices instead (the keys are in
                // effect code·2^32 + index).
                auto delta_i = [&](std::int64_t j) -> int {
                    if (std::uint64_t(j) >= std::uint64_t(count)) return -1;
                    const std::uint64_t x = ci ^ codes[j];
                    return x ? __builtin_clzll(x) : 64 + __builtin_clz(std::uint32_t(i) ^ std::uint32_t(j));
                };
                const int d = delta_i(i + 1) - delta_i(i - 1) > 0 ? 1 : -1;
                const int delta_min = delta_i(i - d);
                std::int64_t l_max = 2;
                while (delta_i(i + l_max * d) > delta_min) l_max *= 2;
                std::int64_t l = 0;
                for (std::int64_t t = l_max / 2; t >= 1; t /= 2) l += delta_i(i + (l + t) * d) > delta_min ? t : 0;
                const std::int64_t j = i + l * d;
                ranges_[ui] = {std::uint32_t(std::min(i, j)), std::uint32_t(std::max(i, j))};
                const int delta_node = delta_i(j);
                std::int64_t s = 0;
                // Ceil-halving search (Karras' Figure 4: t = ⌈l / 2^k⌉), so that a split at any
                // offset of the range can be reached.
                for (int k = 1;; ++k) {
                    const std::int64_t t = (l + (std::int64_t(1) << k) - 1) >> k;
                    s += delta_i(i + (s + t) * d) > delta_node ? t : 0;
                    if (t == 1) break;
                }
                const std::int64_t gamma = i + s * d + std::min(d, 0);
                Node& node = nodes_[ui];
                node.child[0] = std::min(i, j) == gamma ? leaf_base_ + std::uint32_t(gamma) : std::uint32_t(gamma);
                node.child[1] =
                    std::max(i, j) == gamma + 1 ? leaf_base_ + std::uint32_t(gamma + 1) : std::uint32_t(gamma + 1);
                nodes_[node.child[0]].parent = std::uint32_t(ui);
                nodes_[node.child[1]].parent = std::uint32_t(ui);
            }
        });
        nodes_[0].parent = kNullNode;
        lap(phases_.hierarchy);
        // 4. Karras Algorithm 4: bounds bottom up; the first thread to reach a node stops, the
        //    second merges (acq_rel: it sees the first one's child box).
        if (flags_size_ < n - 1) {
            flags_ = std::make_unique<std::atomic<std::uint32_t>[]>(n - 1);
            flags_size_ = n - 1;
        }
        parallel(n - 1, kGrain, [&](std::size_t b, std::size_t e) {
            for (std::size_t i = b; i < e; ++i) flags_[i].store(0, std::memory_order_relaxed);
        });
        // The common box of a node: the intersection of the boxes below, kept only while it is not
        // empty (kShared); once empty it stays empty further up, so most nodes of a scene without
        // crowds never compute one.
        std::atomic<std::size_t> crowds{0};
        auto merge_children = [&](std::uint32_t p) {
            Node& node = nodes_[p];
            const Node& a = nodes_[node.child[0]];
            const Node& c = nodes_[node.child[1]];
            node.box = merge(a.box, c.box);
            node.height = std::uint16_t(1 + std::max(a.height, c.height));
            node.flags = 0;
            if (crowds_checked_ && (a.flags & c.flags & kShared)) {
                const Aabb& ca = is_leaf(node.child[0]) ? a.box : common_[node.child[0]];
                const Aabb& cc = is_leaf(node.child[1]) ? c.box : common_[node.child[1]];
                const Aabb common{rcb::max(ca.min, cc.min), rcb::min(ca.max, cc.max)};
                if (common.min.x <= common.max.x && common.min.y <= common.max.y && common.min.z <= common.max.z) {
                    common_[p] = common;
                    node.flags = kShared;
                    if (ranges_[p][1] - ranges_[p][0] + 1 >= kCrowdLeaves) {
                        node.flags |= kCrowd;
                        crowds.fetch_add(1, std::memory_order_relaxed);
                    }
                }
            }
            return node.parent;
        };
        if (arena_) {
            parallel(n, kGrain, [&](std::size_t b, std::size_t e) {
                for (std::size_t k = b; k < e; ++k) {
                    std::uint32_t p = nodes_[leaf_base_ + k].parent;
                    while (p != kNullNode && flags_[p].fetch_add(1, std::memory_order_acq_rel) != 0)
                        p = merge_children(p);
                }
            });
        } else {
            // One thread: the same walk with plain loads and stores of the flags (a locked
            // read-modify-write per node costs a third of this step and protects nothing here).
            for (std::size_t k = 0; k < n; ++k) {
                std::uint32_t p = nodes_[leaf_base_ + k].parent;
                while (p != kNullNode) {
                    const std::uint32_t seen = flags_[p].load(std::memory_order_relaxed);
                    flags_[p].store(seen + 1, std::memory_order_relaxed);
                    if (seen == 0) break;
                    p = merge_children(p);
                }
            }
        }
        crowds_ = crowds.load();
        lap(phases_.boxes);
    } else {
        common_.clear();
        ranges_.clear();
    }
    stack_.assign(std::size_t(nodes_[0].height) + 2, 0);
}

void LinearBvh::order_equal_codes() {
    const std::size_t n = codes_.size();
    tied_codes_ = 0;
    for (std::size_t b = 0, e; b < n; b = e) {
        for (e = b + 1; e < n && codes_[e] == codes_[b];) ++e;
        if (e - b < 2) continue;
        tied_codes_ += e - b;
        // Keys: the half area's bits (monotone for non-negative floats) above the slot; the slot
        // breaks ties, so the order does not depend on the sort.
        std::uint64_t* keys = codes_tmp_.data();
        for (std::size_t k = b; k < e; ++k) {
            const std::uint32_t slot = order_[k];
            keys[k - b] = std::uint64_t(std::bit_cast<std::uint32_t>(objects_.box(slot).half_area())) << 32 | slot;
        }
        std::sort(keys, keys + (e - b));
        for (std::size_t k = b; k < e; ++k) order_[k] = std::uint32_t(keys[k - b]);
    }
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
    return nodes_.capacity() * sizeof(Node) + objects_.memory_bytes() +
           (codes_.capacity() + codes_tmp_.capacity()) * sizeof(std::uint64_t) +
           (order_.capacity() + order_tmp_.capacity() + histograms_.capacity() + all_counts_.capacity() +
            stack_.capacity()) *
               sizeof(std::uint32_t) +
           flags_size_ * sizeof(std::atomic<std::uint32_t>) + common_.capacity() * sizeof(Aabb) +
           ranges_.capacity() * sizeof(ranges_[0]) + sizeof(*this);
}

nlohmann::json LinearBvh::stats() const {
    return {{"sah_cost", sah_cost()}, {"depth", height()},         {"nodes", nodes_.size()},
            {"crowds", crowds_},      {"tied_codes", tied_codes_}, {"outlier_trimmed", trimmed_}};
}

void LinearBvh::validate() const {
    auto fail = [](const std::string& what) { broken_invariant("lbvh", what); };
    if (dirty_) fail("tree not rebuilt after changes (commit missing)");
    const std::size_t n = objects_.size();
    objects_.validate("lbvh");
    if (nodes_.size() != (n ? 2 * n - 1 : 0))
        fail("node array has " + std::to_string(nodes_.size()) + " nodes for " + std::to_string(n) + " objects");
    for (std::size_t k = 1; k < codes_.size(); ++k)
        if (codes_[k - 1] > codes_[k]) fail("Morton codes not sorted at " + std::to_string(k));
    if (n == 0) return;
    std::vector<std::uint8_t> seen(nodes_.size(), 0);
    std::vector<std::uint32_t> stack{0};
    if (nodes_[0].parent != kNullNode) fail("root has a parent");
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
            if (node.height != 0) fail("leaf with a height");
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
            if (nodes_[c].parent != v)
                fail("child " + std::to_string(c) + " does not point back to " + std::to_string(v));
            if (!node.box.contains(nodes_[c].box))
                fail("node " + std::to_string(v) + " does not enclose child " + std::to_string(c));
            hmax = std::max(hmax, int(nodes_[c].height));
            stack.push_back(c);
        }
        if (node.height != 1 + hmax) fail("node " + std::to_string(v) + " has a wrong height");
    }
    if (leaves != n) fail(std::to_string(n) + " objects but " + std::to_string(leaves) + " leaves reached");
    // Crowds: every inner node's leaf range and common box as the subtree gives them, and the flag
    // set exactly where the rule says.
    std::size_t crowds = 0;
    auto check = [&](auto&& self, std::uint32_t v, std::uint32_t& first, std::uint32_t& last, Aabb& common) -> void {
        if (is_leaf(v)) {
            first = last = v - leaf_base_;
            common = nodes_[v].box;
            if (nodes_[v].flags != kShared) fail("leaf " + std::to_string(v) + " has wrong flags");
            return;
        }
        std::uint32_t f0, l0, f1, l1;
        Aabb c0, c1;
        self(self, nodes_[v].child[0], f0, l0, c0);
        self(self, nodes_[v].child[1], f1, l1, c1);
        if (l0 + 1 != f1) fail("node " + std::to_string(v) + ": its children's leaves are not consecutive");
        first = f0, last = l1;
        common = {rcb::max(c0.min, c1.min), rcb::min(c0.max, c1.max)};
        if (ranges_[v][0] != first || ranges_[v][1] != last)
            fail("node " + std::to_string(v) + " has a wrong leaf range");
        const bool shared =
            common.min.x <= common.max.x && common.min.y <= common.max.y && common.min.z <= common.max.z;
        const bool crowd = crowds_checked_ && last - first + 1 >= kCrowdLeaves && shared;
        if (bool(nodes_[v].flags & kCrowd) != crowd)
            fail("node " + std::to_string(v) +
                 (crowd ? " is a crowd but not marked" : " is marked as a crowd but is none"));
        if (bool(nodes_[v].flags & kShared) != (crowds_checked_ && shared))
            fail("node " + std::to_string(v) + " has a wrong shared flag");
        if ((nodes_[v].flags & kShared) && !(common_[v] == common))
            fail("node " + std::to_string(v) + " has a stale common box");
        crowds += crowd;
    };
    std::uint32_t first, last;
    Aabb common;
    check(check, 0, first, last, common);
    if (first != 0 || last != n - 1) fail("the root does not span every leaf");
    if (crowds != crowds_) fail("crowd count " + std::to_string(crowds_) + ", tree has " + std::to_string(crowds));
    if (stack_.size() < std::size_t(nodes_[0].height) + 2) fail("traversal stack smaller than the depth");
}

}  // namespace rcb
