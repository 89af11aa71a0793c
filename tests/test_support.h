#pragma once
/// Helpers every suite shares: the message of an InputError, temporary folders, and a toy structure to register.

#include <algorithm>
#include <filesystem>
#include <functional>
#include <set>
#include <stdexcept>
#include <string>
#include <tuple>
#include <unordered_map>
#include <vector>

#include <nlohmann/json.hpp>

#include "accel/registry.h"
#include "accel/interface/structure.h"
#include "core/base/geometry.h"
#include "core/base/random.h"
#include "testing/conformance.h"

namespace rcb::test {

/// Expects `f` to throw an InputError whose message contains `substring`; a failure is reported at
/// the caller's line, with the message `f` threw or that it threw none. (__builtin_FILE and
/// __builtin_LINE, not std::source_location: clang 14 with libstdc++ 12 has no source_location.)
void expect_input_error(const std::function<void()>& f, const std::string& substring,
                        const char* file = __builtin_FILE(), int line = __builtin_LINE());

/// An empty folder rcb_<suite>_<pid>_<name> in the system's temporary folder (emptied if it
/// exists), for a test's databases and files.
std::filesystem::path temp_dir(const std::string& suite, const std::string& name);

/// temp_dir(suite, name) for the lifetime of the object, removed with its contents at the end
/// (also when an ASSERT leaves the test early). Without `name`, the running test's name.
class TempDir {
public:
    TempDir(const std::string& suite, const std::string& name);
    explicit TempDir(const std::string& suite);
    ~TempDir();
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;

    const std::filesystem::path& path() const { return path_; }
    /// The path of `name` inside the folder, as a string.
    std::string file(const std::string& name) const { return (path_ / name).string(); }

private:
    std::filesystem::path path_;
};

/// A toy structure as a program outside rcbench would write it, for the tests that register one:
/// the objects in a list, tested in blocks of `block` per ray, front to back or back to front.
/// One tunable integer and one bool, so that it has a tuning space and a fuzzer setting of its own.
class ToyList : public StructureBase<ToyList> {
public:
    struct Params {
        int block = 4;
        bool backwards = false;
        static constexpr auto fields() {
            return std::tuple{Field{"block", &Params::block, 1, 64, "objects tested per block"},
                              Field{"backwards", &Params::backwards, 0, 1, "scan from the last object", kNotTuned}};
        }
    };
    ToyList() : ToyList(Params{}) {}
    explicit ToyList(const Params& p) : params_(p) {}

    void build(std::span<const Object> objects) override {
        objects_.assign(objects.begin(), objects.end());
        index_.clear();
        for (std::size_t i = 0; i < objects_.size(); ++i) index_[objects_[i].uid] = i;
    }
    void insert(const Object& o) override {
        index_[o.uid] = objects_.size();
        objects_.push_back(o);
    }
    void remove(Uid uid) override {
        const std::size_t i = index_.at(uid);
        index_.erase(uid);
        if (i + 1 != objects_.size()) {
            objects_[i] = objects_.back();
            index_[objects_[i].uid] = i;
        }
        objects_.pop_back();
    }
    void move(const Object& o) override { objects_[index_.at(o.uid)].box = o.box; }
    std::size_t size() const override { return objects_.size(); }
    std::size_t memory_bytes() const override { return objects_.capacity() * sizeof(Object) + index_.size() * 32; }
    void check() const override {
        if (index_.size() != objects_.size()) throw std::logic_error("toy: index and list differ in size");
        for (std::size_t i = 0; i < objects_.size(); ++i)
            if (index_.at(objects_[i].uid) != i) throw std::logic_error("toy: index is stale");
    }

    template <class Count, class Visit>
    void traverse(const Segment& s, Count& count, Visit&& visit) {
        const SegmentSlabs slabs(s);
        const std::size_t n = objects_.size(), block = std::size_t(params_.block);
        for (std::size_t start = 0; start < n; start += block) {
            count.traversal();
            const std::size_t end = std::min(n, start + block);
            count.box_tests(end - start);
            for (std::size_t k = start; k < end; ++k) {
                const Object& o = objects_[params_.backwards ? n - 1 - k : k];
                float t_near, t_far;
                if (!slabs.clip(o.box, t_near, t_far)) continue;
                count.hits();
                if (!visit(o.uid, t_near)) return;
            }
        }
    }

private:
    Params params_;
    std::vector<Object> objects_;
    std::unordered_map<Uid, std::size_t> index_;
};

}  // namespace rcb::test
