// rcbench as a library, seen from an engine:
//   (a) a toy engine records its per-frame workload (moving bodies, spawned and despawned
//       projectiles, line-of-sight and ground-probe rays) through rcb::Recorder into a .rcbscene;
//   (b) the engine's own acceleration structure (SweepList, sweep_list.h) is registered with
//       rcb::register_structure and replayed on that recording by rcb::simulate, every ray's hits
//       verified against the ground truth, next to rcbench's brute force and dynamic BVH.
// Prints one table row per structure; exits 1 if any structure missed or invented a hit, 2 on bad
// input (e.g. an unwritable output path).
//
//     engine_integration [out.rcbscene]     (default: <temp dir>/engine_integration.rcbscene)

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include <core/base/error.h>
#include <core/scene/recorder.h>
#include <core/scene/recording_io.h>
#include <accel/registry.h>
#include <sim/simulator.h>
#include <accel/interface/structure.h>

#include "sweep_list.h"

namespace {

using engine::SweepList;
using rcb::Aabb;
using rcb::Uid;
using rcb::Vec3;

// ---------------------------------------------------------------------------------------------
// (a) The toy engine: bodies bouncing in a hall, projectiles that live 30 frames, and per frame
// line-of-sight rays from a player to some bodies plus downward ground probes.

/// splitmix64: the same numbers with every compiler and standard library.
struct Rng {
    std::uint64_t state;
    std::uint64_t next() {
        std::uint64_t z = (state += 0x9e3779b97f4a7c15ull);
        z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
        z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
        return z ^ (z >> 31);
    }
    float uniform(float lo, float hi) { return lo + (hi - lo) * float(next() >> 40) / float(1 << 24); }
};

struct Body {
    Uid id;
    Vec3 pos, vel, half;
    int age = 0;
    Aabb box() const { return {pos - half, pos + half}; }
};

constexpr Vec3 kHall{200, 40, 200};
constexpr float kDt = 1.0f / 60;

void record_engine(const std::string& path, int frames) {
    Rng rng{2024};
    std::vector<Body> bodies, projectiles;
    Uid next_id = 1;
    for (int i = 0; i < 400; ++i) {
        Body b;
        b.id = next_id++;
        b.half = {rng.uniform(0.3f, 2), rng.uniform(0.3f, 2), rng.uniform(0.3f, 2)};
        b.pos = {rng.uniform(2, kHall.x - 2), rng.uniform(2, kHall.y - 2), rng.uniform(2, kHall.z - 2)};
        b.vel = {rng.uniform(-8, 8), rng.uniform(-2, 2), rng.uniform(-8, 8)};
        bodies.push_back(b);
    }
    const Vec3 player{kHall.x / 2, 1.8f, kHall.z / 2};

    rcb::Recorder rec(path, R"({"engine": "engine_integration example", "seed": 2024})");
    for (const Body& b : bodies) rec.insert(b.id, b.box());
    rec.end_frame();  // frame 0: the loaded world

    for (int frame = 1; frame <= frames; ++frame) {
        for (Body& b : bodies) {  // integrate, bounce off the walls
            b.pos = b.pos + b.vel * kDt;
            for (int a = 0; a < 3; ++a)
                if (b.pos[a] - b.half[a] < 0 || b.pos[a] + b.half[a] > kHall[a]) {
                    b.vel[a] = -b.vel[a];
                    b.pos[a] = std::clamp(b.pos[a], b.half[a], kHall[a] - b.half[a]);
                }
            rec.move(b.id, b.box());
        }
        for (Body& p : projectiles) {
            p.pos = p.pos + p.vel * kDt;
            rec.move(p.id, p.box());
        }
        if (frame % 5 == 1)  // fire a volley
            for (int i = 0; i < 4; ++i) {
                Body p;
                p.id = next_id++;
                p.half = {0.1f, 0.1f, 0.1f};
                p.pos = player;
                p.vel = {rng.uniform(-30, 30), rng.uniform(0, 5), rng.uniform(-30, 30)};
                projectiles.push_back(p);
                rec.insert(p.id, p.box());
            }
        std::erase_if(projectiles, [&](Body& p) {
            if (++p.age <= 30) return false;
            rec.remove(p.id);
            return true;
        });
        for (int i = 0; i < 24; ++i)  // line of sight from the player to bodies
            rec.ray({player, bodies[rng.next() % bodies.size()].pos});
        for (int i = 0; i < 8; ++i) {  // ground probes
            const Vec3 top{rng.uniform(0, kHall.x), kHall.y, rng.uniform(0, kHall.z)};
            rec.ray({top, {top.x, 0, top.z}});
        }
        rec.end_frame();
    }
    rec.close();
    std::printf("recorded %d frames, %zu objects live at the end: %s\n", frames, rec.live_count(), path.c_str());
}

double ms(double ns) { return ns / 1e6; }
double us(double ns) { return ns / 1e3; }

}  // namespace

int main(int argc, char** argv) {
    try {
        if (argc > 2) throw rcb::InputError("usage: engine_integration [out.rcbscene]");
        const std::string path =
            argc == 2 ? argv[1] : (std::filesystem::temp_directory_path() / "engine_integration.rcbscene").string();
        record_engine(path, 120);

        rcb::register_structure<SweepList>("sweep", engine::kSweepListSummary);
        const rcb::Recording recording = rcb::read_recording(path);

        struct Run {
            const char* structure;
            nlohmann::json params;
        };
        const Run runs[] = {{"sweep", {{"insertion_sort", true}}},
                            {"sweep", {{"insertion_sort", false}}},
                            {"bf", nlohmann::json::object()},
                            {"dbvh", nlohmann::json::object()}};
        rcb::SimulationOptions options;  // verify every ray against the ground truth
        options.check = true;            // and check each structure's invariants after every commit
        options.warmup_frames = 5;

        std::printf("\n%-6s %-24s %9s %12s %12s %10s %10s\n", "name", "params", "build ms", "update us", "raycast us",
                    "hits", "mismatches");
        std::uint64_t mismatches = 0;
        for (const Run& run : runs) {
            const rcb::SimulationResult r =
                rcb::simulate(recording, rcb::find_structure(run.structure), run.params, options);
            std::uint64_t hits = 0;
            for (const rcb::FrameResult& f : r.frames) hits += f.hits;
            std::printf("%-6s %-24s %9.3f %12.1f %12.1f %10llu %10llu\n", run.structure, run.params.dump().c_str(),
                        ms(double(r.build_ns)), us(r.update_ns().median), us(r.raycast_ns().median),
                        static_cast<unsigned long long>(hits), static_cast<unsigned long long>(r.mismatches()));
            mismatches += r.mismatches();
        }
        std::printf("(update and ray cast: medians per frame over %zu frames after %u warm-up frames)\n",
                    recording.frames.size() - options.warmup_frames, options.warmup_frames);
        if (mismatches != 0) {
            std::fprintf(stderr, "engine_integration: %llu hits differ from the ground truth\n",
                         static_cast<unsigned long long>(mismatches));
            return 1;
        }
        return 0;
    } catch (const rcb::InputError& e) {
        std::fprintf(stderr, "engine_integration: %s\n", e.what());
        return 2;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "engine_integration: %s\n", e.what());
        return 1;
    }
}
