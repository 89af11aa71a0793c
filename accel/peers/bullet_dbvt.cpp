#include "accel/peers/bullet_dbvt.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include <BulletCollision/BroadphaseCollision/btDbvt.h>

namespace rcb {

struct BulletRayScratch::Stack {
    btAlignedObjectArray<const btDbvtNode*> nodes;
};

BulletRayScratch::BulletRayScratch() = default;
BulletRayScratch::~BulletRayScratch() = default;
BulletRayScratch::BulletRayScratch(BulletRayScratch&&) noexcept = default;
BulletRayScratch& BulletRayScratch::operator=(BulletRayScratch&&) noexcept = default;

std::size_t BulletRayScratch::memory_bytes() const {
    return stack ? sizeof(Stack) + std::size_t(stack->nodes.capacity()) * sizeof(const btDbvtNode*) : 0;
}

namespace {

/// Hands every leaf btDbvt's ray test reaches to the exact collector. rayTestInternal has no way
/// to end its walk, so after a stop the collector declines the remaining leaves untested.
struct OfferLeaves : btDbvt::ICollide {
    ExactCollector* collect;
    explicit OfferLeaves(ExactCollector* c) : collect(c) {}
    void Process(const btDbvtNode* leaf) override { collect->offer(static_cast<std::uint32_t>(leaf->dataAsInt)); }
};

}  // namespace

BulletDbvt::BulletDbvt() : BulletDbvt(Params{}) {}

BulletDbvt::BulletDbvt(const Params& params)
    : params_(params),
      variant_(parse_choice<Variant>(kVariantChoices, params.variant, "bullet_dbvt variant")),
      trees_{std::make_unique<btDbvt>(), std::make_unique<btDbvt>()} {
    set_cast_threads(params.cast_threads);
}

void BulletDbvt::fit(BulletRayScratch& scratch) const {
    if (!scratch.stack) scratch.stack = std::make_unique<BulletRayScratch::Stack>();
}

BulletDbvt::~BulletDbvt() = default;

void BulletDbvt::build(std::span<const Object> objects) {
    for (auto& tree : trees_) tree->clear();
    objects_.clear();
    leaves_.clear();
    stage_.clear();
    position_.clear();
    for (auto& list : staged_) list.clear();
    stage_current_ = 0;
    fixed_left_ = 0;
    scale_ = 0;
    for (const Object& o : objects) scale_ = std::max(scale_, largest_coordinate(o.box));
    scale_ = std::max(scale_, std::numeric_limits<float>::min());
    for (const Object& o : objects) insert(o);
}

btDbvtAabbMm BulletDbvt::volume_of(std::uint32_t slot) const {
    const float pad = this->pad();
    const Aabb& b = objects_.box(slot);
    return btDbvtVolume::FromMM(btVector3(b.min.x - pad, b.min.y - pad, b.min.z - pad),
                                btVector3(b.max.x + pad, b.max.y + pad, b.max.z + pad));
}

void BulletDbvt::insert_leaf(std::uint32_t slot, btDbvt& tree) {
    leaves_[slot] = tree.insert(volume_of(slot), nullptr);
    leaves_[slot]->dataAsInt = static_cast<int>(slot);
}

void BulletDbvt::set_stage(std::uint32_t slot, std::uint8_t stage) {
    if (stage_[slot] != kFixed) {  // off its list: the list's last slot takes its place
        std::vector<std::uint32_t>& list = staged_[stage_[slot]];
        const std::uint32_t last = list.back();
        list[position_[slot]] = last;
        position_[last] = position_[slot];
        list.pop_back();
    }
    stage_[slot] = stage;
    if (stage != kFixed) {
        position_[slot] = std::uint32_t(staged_[stage].size());
        staged_[stage].push_back(slot);
    }
}

void BulletDbvt::update_leaf(std::uint32_t slot, const Aabb& old) {
    btDbvtNode* leaf = leaves_[slot];
    btDbvtAabbMm volume = volume_of(slot);
    if (variant_ == Variant::raw) {  // remove and reinsert, as the peer always did
        trees_[0]->update(leaf, volume);
        ++reinserts_;
        return;
    }
    // btDbvtBroadphase::setAabb.
    if (stage_[slot] == kFixed) {  // fixed -> dynamic set, tight
        trees_[1]->remove(leaf);
        insert_leaf(slot, *trees_[0]);
        ++reinserts_;
    } else if (Intersect(leaf->volume, volume)) {  // moving: grown by the margin and the prediction
        const Aabb& b = objects_.box(slot);
        const btVector3 delta(b.min.x - old.min.x, b.min.y - old.min.y, b.min.z - old.min.z);
        btVector3 velocity = (btVector3(old.max.x, old.max.y, old.max.z) - btVector3(old.min.x, old.min.y, old.min.z)) /
                             btScalar(2) * btScalar(params_.prediction);
        for (int a = 0; a < 3; ++a)
            if (delta[a] < 0) velocity[a] = -velocity[a];
        if (trees_[0]->update(leaf, volume, velocity, btScalar(params_.margin)))
            ++reinserts_;
        else
            ++skipped_;
    } else {  // teleporting: tight
        trees_[0]->update(leaf, volume);
        ++reinserts_;
    }
    set_stage(slot, stage_current_);
}

void BulletDbvt::cover(const Aabb& box) {
    const float m = largest_coordinate(box);
    if (m <= scale_) return;
    const float old_pad = pad();
    scale_ = std::max(2 * m, std::numeric_limits<float>::min());
    ++repads_;
    // Every leaf grown in place by the padding's growth: fat volumes stay fat.
    const btScalar grow = pad() - old_pad;
    for (std::uint32_t i = 0; i < objects_.size(); ++i) {
        if (!leaves_[i]) continue;  // the slot being inserted
        btDbvtAabbMm volume = leaves_[i]->volume;
        volume.Expand(btVector3(grow, grow, grow));
        tree_of(i).update(leaves_[i], volume);
    }
}

void BulletDbvt::insert(const Object& o) {
    const std::uint32_t slot = objects_.insert(o);
    leaves_.push_back(nullptr);
    stage_.push_back(kFixed);
    position_.push_back(0);
    cover(o.box);
    insert_leaf(slot, *trees_[0]);  // btDbvtBroadphase::createProxy: the dynamic set, tight
    set_stage(slot, stage_current_);
}

void BulletDbvt::remove(Uid uid) {
    const std::uint32_t slot = objects_.remove(uid);
    tree_of(slot).remove(leaves_[slot]);
    set_stage(slot, kFixed);  // off its list
    const auto last = std::uint32_t(leaves_.size() - 1);
    if (slot != last) {  // the last slot's object moved into `slot`
        leaves_[slot] = leaves_[last];
        leaves_[slot]->dataAsInt = static_cast<int>(slot);
        stage_[slot] = stage_[last];
        position_[slot] = position_[last];
        if (stage_[slot] != kFixed) staged_[stage_[slot]][position_[slot]] = slot;
    }
    leaves_.pop_back();
    stage_.pop_back();
    position_.pop_back();
}

void BulletDbvt::move(const Object& o) {
    Aabb old;
    const std::uint32_t slot = objects_.move(o, &old);
    cover(o.box);
    update_leaf(slot, old);
}

void BulletDbvt::retire_stage() {
    stage_current_ = std::uint8_t((stage_current_ + 1) % kStages);
    std::vector<std::uint32_t>& list = staged_[stage_current_];
    if (list.empty()) return;
    for (const std::uint32_t slot : list) {
        trees_[0]->remove(leaves_[slot]);
        insert_leaf(slot, *trees_[1]);
        stage_[slot] = kFixed;
    }
    retired_ += list.size();
    list.clear();
    fixed_left_ = trees_[1]->m_leaves;
}

void BulletDbvt::commit() {
    // btDbvtBroadphase::collide: the dynamic set's passes, the fixed set's while it has leaves left
    // to optimise, then the stage advance (the pair cache's work there has no counterpart for rays).
    const int passes = params_.optimize_passes + trees_[0]->m_leaves * params_.dynamic_updates / 100;
    if (passes > 0) trees_[0]->optimizeIncremental(passes);
    if (variant_ == Variant::raw) return;
    if (fixed_left_ > 0) {
        const int count = 1 + trees_[1]->m_leaves * params_.fixed_updates / 100;
        trees_[1]->optimizeIncremental(count);
        fixed_left_ = std::max(0, fixed_left_ - count);
    }
    retire_stage();
}

bool BulletDbvt::dbvt_query(const Segment& s, ExactCollector& collect, Counting* count,
                            BulletRayScratch& scratch) const {
    if (scale_ < kMinScale || !within_reach(s, kFarFactor * scale_)) return false;
    const btVector3 from(s.p0.x, s.p0.y, s.p0.z), to(s.p1.x, s.p1.y, s.p1.z);
    const btVector3 d = to - from;
    // As btDbvt::rayTest does, but unnormalised so that λ ∈ [0, 1] is the segment itself.
    btVector3 inv;
    unsigned signs[3];
    for (int a = 0; a < 3; ++a) {
        inv[a] = d[a] == btScalar(0) ? btScalar(BT_LARGE_FLOAT) : btScalar(1) / d[a];
        signs[a] = inv[a] < btScalar(0);
    }
    OfferLeaves leaves(&collect);
    const btVector3 zero(0, 0, 0);
    if (!count) {  // btDbvtBroadphase::rayTest: the dynamic set, then the fixed set
        for (const auto& tree : trees_)
            tree->rayTestInternal(tree->m_root, from, to, inv, signs, btScalar(1), zero, zero, scratch.stack->nodes,
                                  leaves);
        return true;
    }
    // The counting pass: btDbvt::rayTestInternal's walk step for step (the same node test in the
    // same order, so the same leaves reach the collector), with its node visits counted; the
    // library's own loop offers no hook for them.
    std::vector<const btDbvtNode*>& stack = counting_stack_;
    stack.clear();
    for (const auto& tree : trees_)
        if (tree->m_root) stack.push_back(tree->m_root);
    std::reverse(stack.begin(), stack.end());  // the dynamic set first
    while (!stack.empty()) {
        const btDbvtNode* node = stack.back();
        stack.pop_back();
        count->traversal();
        btVector3 bounds[2] = {node->volume.Mins(), node->volume.Maxs()};
        btScalar t_min = 1, lambda_min = 0;
        if (!btRayAabb2(from, inv, signs, bounds, t_min, lambda_min, btScalar(1))) continue;
        if (node->isinternal()) {
            count->node_hits(2);
            stack.push_back(node->childs[0]);
            stack.push_back(node->childs[1]);
        } else {
            leaves.Process(node);
        }
    }
    return true;
}

std::size_t BulletDbvt::memory_bytes() const {
    std::size_t bytes = objects_.memory_bytes() + leaves_.capacity() * sizeof(btDbvtNode*) + stage_.capacity() +
                        position_.capacity() * sizeof(std::uint32_t);
    for (const auto& list : staged_) bytes += list.capacity() * sizeof(std::uint32_t);
    // btDbvt: 2n − 1 nodes plus the one cached free node per tree, and the ray stack.
    for (const auto& tree : trees_) {
        const std::size_t nodes = tree->m_leaves ? 2 * std::size_t(tree->m_leaves) - 1 : 0;
        bytes += (nodes + (tree->m_free ? 1 : 0)) * sizeof(btDbvtNode) + sizeof(btDbvt);
    }
    bytes += scratch_bytes() + counting_stack_.capacity() * sizeof(const btDbvtNode*);
    return bytes + sizeof(*this);
}

nlohmann::json BulletDbvt::stats() const {
    auto depth = [](const btDbvt& tree) { return tree.m_root ? btDbvt::maxdepth(tree.m_root) : 0; };
    return {{"depth", std::max(depth(*trees_[0]), depth(*trees_[1]))},
            {"fixed_leaves", trees_[1]->m_leaves},
            {"reinserts", reinserts_},
            {"skipped", skipped_},
            {"retired", retired_},
            {"repads", repads_},
            {"pad", pad()}};
}

namespace {

/// The root above `node`.
const btDbvtNode* root_of(const btDbvtNode* node) {
    while (node->parent) node = node->parent;
    return node;
}

/// Every internal node of `tree` encloses its children and is their parent.
void check_tree(const btDbvt& tree) {
    std::vector<const btDbvtNode*> stack;
    if (tree.m_root) stack.push_back(tree.m_root);
    while (!stack.empty()) {
        const btDbvtNode* node = stack.back();
        stack.pop_back();
        if (node->isleaf()) continue;
        for (const btDbvtNode* child : node->childs) {
            if (child->parent != node) broken_invariant("bullet_dbvt", "child's parent link is wrong");
            if (!node->volume.Contain(child->volume))
                broken_invariant("bullet_dbvt", "node does not enclose its child");
            stack.push_back(child);
        }
    }
}

}  // namespace

void BulletDbvt::check() const {
    const std::size_t n = objects_.size();
    objects_.check("bullet_dbvt");
    if (leaves_.size() != n || stage_.size() != n || position_.size() != n)
        broken_invariant("bullet_dbvt", "slot arrays differ in size");
    if (std::size_t(trees_[0]->m_leaves + trees_[1]->m_leaves) != n)
        broken_invariant("bullet_dbvt", "trees have " + std::to_string(trees_[0]->m_leaves + trees_[1]->m_leaves) +
                                            " leaves for " + std::to_string(n) + " objects");
    if (variant_ == Variant::raw && trees_[1]->m_leaves != 0) broken_invariant("bullet_dbvt", "raw has a fixed set");
    const float pad = this->pad();
    for (std::uint32_t i = 0; i < n; ++i) {
        if (!leaves_[i] || !leaves_[i]->isleaf() || leaves_[i]->dataAsInt != int(i))
            broken_invariant("bullet_dbvt", "leaf of slot " + std::to_string(i) + " does not point back");
        const btDbvt& tree = *trees_[stage_[i] == kFixed ? 1 : 0];
        if (root_of(leaves_[i]) != tree.m_root)
            broken_invariant("bullet_dbvt", "leaf of slot " + std::to_string(i) + " is not in its set's tree");
        if (stage_[i] != kFixed && (position_[i] >= staged_[stage_[i]].size() || staged_[stage_[i]][position_[i]] != i))
            broken_invariant("bullet_dbvt", "slot " + std::to_string(i) + " is not on its stage's list");
        const Aabb& b = objects_.box(i);
        const btVector3 lo = leaves_[i]->volume.Mins(), hi = leaves_[i]->volume.Maxs();
        // The leaf volume must enclose the box with the padding (the exactness argument needs it).
        if (lo.x() > b.min.x - pad * 0.5f || lo.y() > b.min.y - pad * 0.5f || lo.z() > b.min.z - pad * 0.5f ||
            hi.x() < b.max.x + pad * 0.5f || hi.y() < b.max.y + pad * 0.5f || hi.z() < b.max.z + pad * 0.5f)
            broken_invariant("bullet_dbvt",
                             "leaf of uid " + std::to_string(objects_.uid(i)) + " does not enclose its padded box");
    }
    if (staged_[0].size() + staged_[1].size() + std::size_t(trees_[1]->m_leaves) != n)
        broken_invariant("bullet_dbvt", "stage lists do not hold every dynamic slot");
    for (const auto& tree : trees_) check_tree(*tree);
}

}  // namespace rcb
