#include "core/accel/peers/bullet_dbvt.h"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include <BulletCollision/BroadphaseCollision/btDbvt.h>

namespace rcb {

struct BulletDbvt::Stack {
    btAlignedObjectArray<const btDbvtNode*> nodes;
};

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
    : params_(params), tree_(std::make_unique<btDbvt>()), stack_(std::make_unique<Stack>()) {}

BulletDbvt::~BulletDbvt() = default;

void BulletDbvt::build(std::span<const Object> objects) {
    tree_->clear();
    objects_.clear();
    leaves_.clear();
    scale_ = 0;
    for (const Object& o : objects) scale_ = std::max(scale_, largest_coordinate(o.box));
    scale_ = std::max(scale_, std::numeric_limits<float>::min());
    for (const Object& o : objects) insert(o);
}

void BulletDbvt::set_leaf(std::uint32_t slot) {
    const float pad = this->pad();
    const Aabb& b = objects_.box(slot);
    btDbvtVolume v = btDbvtVolume::FromMM(btVector3(b.min.x - pad, b.min.y - pad, b.min.z - pad),
                                          btVector3(b.max.x + pad, b.max.y + pad, b.max.z + pad));
    if (leaves_[slot]) {
        tree_->update(leaves_[slot], v);
    } else {
        leaves_[slot] = tree_->insert(v, nullptr);
    }
    leaves_[slot]->dataAsInt = static_cast<int>(slot);
}

void BulletDbvt::cover(const Aabb& box) {
    const float m = largest_coordinate(box);
    if (m <= scale_) return;
    scale_ = std::max(2 * m, std::numeric_limits<float>::min());
    ++repads_;
    for (std::uint32_t i = 0; i < objects_.size(); ++i) set_leaf(i);
}

void BulletDbvt::insert(const Object& o) {
    const std::uint32_t slot = objects_.insert(o);
    leaves_.push_back(nullptr);
    cover(o.box);
    set_leaf(slot);
}

void BulletDbvt::remove(Uid uid) {
    const std::uint32_t slot = objects_.remove(uid);
    tree_->remove(leaves_[slot]);
    if (slot != leaves_.size() - 1) {  // the last slot's object moved into `slot`
        leaves_[slot] = leaves_.back();
        leaves_[slot]->dataAsInt = static_cast<int>(slot);
    }
    leaves_.pop_back();
}

void BulletDbvt::move(const Object& o) {
    const std::uint32_t slot = objects_.move(o);
    cover(o.box);
    set_leaf(slot);
}

void BulletDbvt::commit() {
    if (params_.optimize_passes > 0) tree_->optimizeIncremental(params_.optimize_passes);
}

bool BulletDbvt::dbvt_query(const Segment& s, ExactCollector& collect, Counting* count) {
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
    if (!count) {
        tree_->rayTestInternal(tree_->m_root, from, to, inv, signs, btScalar(1), zero, zero, stack_->nodes, leaves);
        return true;
    }
    // The counting pass: btDbvt::rayTestInternal's walk step for step (the same node test in the
    // same order, so the same leaves reach the collector), with its node visits counted; the
    // library's own loop offers no hook for them.
    std::vector<const btDbvtNode*>& stack = counting_stack_;
    stack.assign(1, tree_->m_root);
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
    std::size_t bytes = objects_.memory_bytes() + leaves_.capacity() * sizeof(btDbvtNode*);
    // btDbvt: 2n − 1 nodes plus the one cached free node, and the ray stack.
    const std::size_t nodes = tree_->m_leaves ? 2 * std::size_t(tree_->m_leaves) - 1 : 0;
    bytes += (nodes + (tree_->m_free ? 1 : 0)) * sizeof(btDbvtNode);
    bytes += std::size_t(stack_->nodes.capacity()) * sizeof(const btDbvtNode*);
    return bytes + sizeof(*this) + sizeof(btDbvt);
}

nlohmann::json BulletDbvt::stats() const {
    const int depth = tree_->m_root ? btDbvt::maxdepth(tree_->m_root) : 0;
    return {{"depth", depth}, {"repads", repads_}, {"pad", pad()}};
}

void BulletDbvt::validate() const {
    const std::size_t n = objects_.size();
    objects_.validate("bullet_dbvt");
    if (leaves_.size() != n) broken_invariant("bullet_dbvt", "slot arrays differ in size");
    if (std::size_t(tree_->m_leaves) != n)
        broken_invariant("bullet_dbvt", "tree has " + std::to_string(tree_->m_leaves) + " leaves for " +
                                            std::to_string(n) + " objects");
    const float pad = this->pad();
    for (std::size_t i = 0; i < n; ++i) {
        if (!leaves_[i] || !leaves_[i]->isleaf() || leaves_[i]->dataAsInt != int(i))
            broken_invariant("bullet_dbvt", "leaf of slot " + std::to_string(i) + " does not point back");
        const Aabb& b = objects_.box(i);
        const btVector3 lo = leaves_[i]->volume.Mins(), hi = leaves_[i]->volume.Maxs();
        // The leaf volume must enclose the box with the padding (the exactness argument needs it).
        if (lo.x() > b.min.x - pad * 0.5f || lo.y() > b.min.y - pad * 0.5f || lo.z() > b.min.z - pad * 0.5f ||
            hi.x() < b.max.x + pad * 0.5f || hi.y() < b.max.y + pad * 0.5f || hi.z() < b.max.z + pad * 0.5f)
            broken_invariant("bullet_dbvt",
                             "leaf of uid " + std::to_string(objects_.uid(i)) + " does not enclose its padded box");
    }
    // Every internal node encloses its children and is their parent.
    std::vector<const btDbvtNode*> stack;
    if (tree_->m_root) stack.push_back(tree_->m_root);
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

}  // namespace rcb
