#pragma once
/// A test structure made from another: it keeps an `Inner` structure and forwards every update,
/// size and check to it, so that a deliberately wrong or slow variant writes only its traversal
/// (which reads `inner_`).

#include <cstddef>
#include <span>
#include <utility>

#include "accel/interface/structure.h"

namespace rcb::test {

template <class Derived, class Inner>
class Forwarding : public StructureBase<Derived> {
public:
    template <class... Args>
    explicit Forwarding(Args&&... inner_args) : inner_(std::forward<Args>(inner_args)...) {}

    void build(std::span<const Object> objects) override { inner_.build(objects); }
    void insert(const Object& o) override { inner_.insert(o); }
    void remove(Uid uid) override { inner_.remove(uid); }
    void move(const Object& o) override { inner_.move(o); }
    std::size_t size() const override { return inner_.size(); }
    std::size_t memory_bytes() const override { return inner_.memory_bytes(); }
    void check() const override { inner_.check(); }

protected:
    Inner inner_;
};

}  // namespace rcb::test
