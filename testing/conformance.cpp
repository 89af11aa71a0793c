// The conformance suite's checks (testing/conformance.h): exactness against the ground truth with
// check() after every frame, random parameters from the ParamSpecs, the fuzz scene, and the
// refusal of bad parameters.
#include "testing/conformance.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <exception>
#include <sstream>

#include "core/base/error.h"
#include "sim/simulator.h"
#include "testing/differential_settings.h"

namespace rcb::test {

std::string input_error_of(const std::function<void()>& f) {
    try {
        f();
    } catch (const InputError& e) {
        return e.what();
    }
    return "";
}

namespace {

/// A number in [lo, hi]: an end one time in four, else uniform or log-uniform (see random_params).
double random_in_range(const ParamSpec& p, Random& rng) {
    const std::uint64_t pick = rng.below(8);
    if (pick == 0) return p.lo;
    if (pick == 1) return p.hi;
    const bool integer = p.kind == ParamKind::integer;
    const bool wide = p.log_scale || p.hi >= 32 * std::max(p.lo, 1.0);
    if (!wide) return integer ? p.lo + double(rng.below(std::uint64_t(p.hi - p.lo) + 1)) : rng.uniform(p.lo, p.hi);
    if (integer) {
        const double lo = std::max(p.lo, 1.0);
        return std::min(p.hi, std::floor(rng.log_uniform(lo, p.hi + 1)));
    }
    return rng.log_uniform(p.lo > 0 ? p.lo : p.hi * 1e-4, p.hi);
}

nlohmann::json draw(const StructureInfo& info, Random& rng, const std::set<std::string>& keep_default) {
    nlohmann::json params = nlohmann::json::object();
    for (const ParamSpec& p : info.params) {
        if (rng.below(4) == 0 || keep_default.contains(p.name)) continue;  // its default
        switch (p.kind) {
            case ParamKind::boolean:
                params[p.name] = rng.below(2) == 1;
                break;
            case ParamKind::choice:
                params[p.name] = p.choices[rng.below(p.choices.size())];
                break;
            case ParamKind::integer:
                params[p.name] = std::int64_t(random_in_range(p, rng));
                break;
            case ParamKind::real:
                params[p.name] = random_in_range(p, rng);
                break;
        }
    }
    return params;
}

std::string point_text(const Vec3& p) {
    std::ostringstream out;
    out.precision(9);
    out << '(' << p.x << ", " << p.y << ", " << p.z << ')';
    return out.str();
}

}  // namespace

std::string describe_mismatches(const SimulationResult& res, const Recording& r, const std::string& scene_name) {
    static const char* what[] = {"missed", "extra", "duplicate"};
    std::string out;
    for (const auto& [frame, d] : res.examples) {
        out += "\n  scene " + scene_name + " frame " + std::to_string(frame) + " ray " + std::to_string(d.ray);
        if (frame >= 1 && frame <= r.frames.size() && d.ray < r.frames[frame - 1].rays.size()) {
            const Frame& f = r.frames[frame - 1];
            out += std::string(" (") + query_kind_name(f.kind(d.ray)) + ") from " + point_text(f.rays[d.ray].p0) +
                   " to " + point_text(f.rays[d.ray].p1);
        }
        out += std::string(": ") + what[d.kind] + " uid " + std::to_string(d.uid);
    }
    return out;
}

nlohmann::json random_params(const StructureInfo& info, Random& rng, const std::set<std::string>& keep_default) {
    for (int attempt = 0; attempt < 100; ++attempt) {
        nlohmann::json params = draw(info, rng, keep_default);
        const std::string refused = input_error_of([&] { info.make(params, "params"); });
        if (refused.empty()) return params;
        // A refusal names the parameter path it refuses, as every bad input must.
        EXPECT_EQ(refused.rfind("params", 0), 0u) << info.name << ' ' << params.dump() << ": " << refused;
    }
    ADD_FAILURE() << info.name << ": 100 parameter sets drawn from its specs, every one refused";
    return nlohmann::json::object();
}

std::string ground_truth_failures(const Recording& r, const StructureInfo& info, const nlohmann::json& params,
                                  const std::string& scene_name) {
    SimulationOptions o;
    o.verify = true;
    o.count = true;
    o.check = true;
    const std::string who = info.name + ' ' + params.dump() + " on scene " + scene_name;
    try {
        const SimulationResult res = simulate(r, info, params, o);
        if (res.mismatches() == 0) return "";
        return who + ": " + std::to_string(res.mismatches()) + " mismatches against the ground truth" +
               describe_mismatches(res, r, scene_name);
    } catch (const std::exception& e) {
        return who + ": " + e.what();
    }
}

std::string refusal_failures(const StructureInfo& info) {
    std::string out;
    auto expect_refused = [&](const nlohmann::json& params, const std::string& path) {
        const std::string message = input_error_of([&] { info.make(params, "params"); });
        if (message.empty())
            out += info.name + ": accepted " + params.dump() + "\n";
        else if (message.rfind(path + ':', 0) != 0)
            out += info.name + ": refused " + params.dump() + " without naming " + path + ": " + message + "\n";
    };
    for (const ParamSpec& p : info.params) {
        const std::string path = "params." + p.name;
        switch (p.kind) {
            case ParamKind::boolean:
                expect_refused({{p.name, 1}}, path);
                break;
            case ParamKind::choice:
                expect_refused({{p.name, "no-such-choice"}}, path);
                break;
            case ParamKind::integer:
                expect_refused({{p.name, p.lo + 0.5}}, path);
                [[fallthrough]];
            case ParamKind::real:
                expect_refused({{p.name, p.lo - std::max(1.0, std::abs(p.lo))}}, path);
                expect_refused({{p.name, p.hi + std::max(1.0, std::abs(p.hi))}}, path);
                expect_refused({{p.name, "x"}}, path);
                break;
        }
    }
    expect_refused({{"no_such_parameter", 1}}, "params.no_such_parameter");
    expect_refused(nlohmann::json::array(), "params");
    return out;
}

std::uint64_t conformance_seed() {
    const char* text = std::getenv("RCB_CONFORMANCE_SEED");
    return text != nullptr && *text != '\0' ? std::stoull(text) : 20231;
}

void expect_exact_on_hard_scenes(const StructureInfo& info, const nlohmann::json& params) {
    static const std::vector<NamedScene> scenes = [] {
        std::vector<NamedScene> out = hard_scenes();
        for (NamedScene& s : out) s.recording = with_every_query_kind(std::move(s.recording));
        return out;
    }();
    for (const NamedScene& s : scenes) {
        const std::string failures = ground_truth_failures(s.recording, info, params, s.name);
        EXPECT_TRUE(failures.empty()) << failures;
    }
}

void expect_exact_at_random_params(const StructureInfo& info, std::uint64_t seed, int draws) {
    // One stream per structure, so that adding a structure leaves the others' draws alone.
    std::uint64_t stream = seed;
    for (const char c : info.name) stream = stream * 131 + std::uint8_t(c);
    Random rng(stream);
    // Guards (the *_guard switches) stay on: off, they lift the bounds on memory and time that keep
    // a hard scene small (hg without its entries guard splits without limit).
    std::set<std::string> guards;
    for (const ParamSpec& p : info.params)
        if (p.name.ends_with("_guard")) guards.insert(p.name);
    for (int d = 0; d < draws; ++d) {
        const nlohmann::json params = random_params(info, rng, guards);
        SCOPED_TRACE("RCB_CONFORMANCE_SEED=" + std::to_string(seed) + ", draw " + std::to_string(d));
        expect_exact_on_hard_scenes(info, params);
    }
}

void expect_exact_under_fuzz(const StructureInfo& info, std::uint64_t seed, std::uint32_t frames) {
    const Recording r = fuzz_scene(seed, frames);
    const std::string name = "fuzz (RCB_CONFORMANCE_SEED=" + std::to_string(seed) + ")";
    for (const nlohmann::json& params : fuzz::differential_settings(info)) {
        const std::string failures = ground_truth_failures(r, info, params, name);
        EXPECT_TRUE(failures.empty()) << failures;
    }
}

void expect_refuses_bad_params(const StructureInfo& info) {
    const std::string failures = refusal_failures(info);
    EXPECT_TRUE(failures.empty()) << failures;
}

}  // namespace rcb::test
