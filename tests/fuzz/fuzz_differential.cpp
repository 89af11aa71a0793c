/// libFuzzer target: differential test of every registered structure against brute force.
///
/// The input becomes a small scene and its changes: objects and rays on a coarse lattice (so that
/// faces, edges and centroids coincide often), zero-size boxes, huge and far coordinates, removes,
/// moves and inserts over a few frames, axis-parallel and zero-length rays. Every registered
/// structure, at its defaults and at the settings its ParamSpecs give (differential_settings.h:
/// each choice and bool value, guards off, every number at the low end of its range), replays
/// it through the simulator with verification against the double-precision ground truth and
/// check() after every frame. A mismatch or a failed invariant aborts.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <fuzzer/FuzzedDataProvider.h>

#include "core/base/error.h"
#include "core/scene/recording_io.h"
#include "accel/registry.h"
#include "sim/simulator.h"
#include "testing/differential_settings.h"

namespace {

using rcb::Aabb;
using rcb::Vec3;

float coordinate(FuzzedDataProvider& in) {
    const std::uint8_t kind = in.ConsumeIntegral<std::uint8_t>();
    const float v = float(in.ConsumeIntegral<std::int8_t>()) * 0.25f;
    if (kind < 240) return v;                                       // the lattice: coincident faces
    if (kind < 250) return v * 1e6f;                                // far away (outliers)
    return v + float(in.ConsumeIntegral<std::uint16_t>()) * 1e-5f;  // just off the lattice
}

Vec3 point(FuzzedDataProvider& in) { return {coordinate(in), coordinate(in), coordinate(in)}; }

Aabb box(FuzzedDataProvider& in) {
    const Vec3 p = point(in);
    Vec3 e;
    for (int a = 0; a < 3; ++a) {
        const std::uint8_t b = in.ConsumeIntegral<std::uint8_t>();
        e[a] = b < 64 ? 0.0f : (b < 250 ? float(b - 63) * 0.125f : 1e5f);  // flat, ordinary, huge
    }
    return {p, p + e};
}

rcb::Segment ray(FuzzedDataProvider& in) {
    const Vec3 p = point(in);
    const std::uint8_t shape = in.ConsumeIntegral<std::uint8_t>();
    if (shape < 32) return {p, p};  // zero length
    Vec3 q = point(in);
    if (shape < 128) {  // axis-parallel: along a lattice line or face
        const int axis = shape % 3;
        for (int a = 0; a < 3; ++a)
            if (a != axis) q[a] = p[a];
    }
    return {p, q};
}

rcb::Recording scene(FuzzedDataProvider& in) {
    rcb::Recording r;
    r.meta = R"({"generator":"fuzz"})";
    rcb::Uid next = 1;
    const int objects = in.ConsumeIntegralInRange(0, 48);
    for (int i = 0; i < objects; ++i) r.initial.push_back({next++, box(in)});
    rcb::LiveSet live(r.initial);
    const int frames = in.ConsumeIntegralInRange(1, 5);
    for (int f = 0; f < frames && in.remaining_bytes() > 0; ++f) {
        rcb::Frame frame;
        std::vector<rcb::Uid> touched;
        auto untouched = [&](rcb::Uid u) {
            for (rcb::Uid t : touched)
                if (t == u) return false;
            return true;
        };
        const int changes = in.ConsumeIntegralInRange(0, 8);
        for (int c = 0; c < changes; ++c) {
            const int what = in.ConsumeIntegralInRange(0, 2);
            if (what == 0 || live.size() == 0) {
                frame.inserts.push_back({next++, box(in)});
                continue;
            }
            const rcb::Uid uid = live.objects()[in.ConsumeIntegralInRange<std::size_t>(0, live.size() - 1)].uid;
            if (!untouched(uid)) continue;
            touched.push_back(uid);
            if (what == 1)
                frame.removes.push_back(uid);
            else
                frame.moves.push_back({uid, box(in)});
        }
        const int rays = in.ConsumeIntegralInRange(1, 16);
        for (int k = 0; k < rays; ++k) frame.rays.push_back(ray(in));
        live.apply(frame);
        r.frames.push_back(std::move(frame));
    }
    return r;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    FuzzedDataProvider in(data, size);
    const rcb::Recording r = scene(in);
    try {
        rcb::refuse_invalid_recording(r, "fuzz scene");
    } catch (const rcb::InputError&) {
        return 0;  // not a legal recording (cannot happen by construction; kept as a guard)
    }
    rcb::SimulationOptions o;
    o.verify = true;
    o.count = true;
    o.check = true;
    static const auto plan = rcb::fuzz::differential_plan();
    for (const auto& [info, settings] : plan) {
        for (const nlohmann::json& params : settings) {
            const rcb::SimulationResult res = rcb::simulate(r, *info, params, o);
            if (res.mismatches() != 0) {
                std::fprintf(stderr, "%s %s: %llu mismatches\n", info->name.c_str(), params.dump().c_str(),
                             static_cast<unsigned long long>(res.mismatches()));
                for (const auto& [frame, d] : res.examples)
                    std::fprintf(stderr, "  frame %u ray %zu uid %llu kind %d\n", frame, std::size_t(d.ray),
                                 static_cast<unsigned long long>(d.uid), int(d.kind));
                std::abort();
            }
        }
    }
    return 0;
}
