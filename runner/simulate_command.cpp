// rcbench simulate: one structure over one recording, as a table (thesis Tables 6.1/6.2) or JSON.
#include <iostream>
#include <memory>

#include "core/recording_io.h"
#include "core/simulator.h"
#include "runner/commands.h"
#include "runner/structure_options.h"
#include "runner/table.h"

namespace rcb {
namespace {

void print_table(const std::string& scene, const SimulationResult& res) {
    std::cout << "scene      " << scene << " (" << res.objects << " objects, " << res.frames.size() << " frames)\n"
              << "structure  " << res.structure << ' ' << res.params.dump() << '\n'
              << "build      " << fixed(res.build_ns / 1e6, 3) << " ms   memory " << bytes_text(double(res.memory_bytes))
              << " (" << fixed(res.objects ? double(res.memory_bytes) / double(res.objects) : 0.0, 1) << " B/object)\n\n";
    TextTable t({"frame", "changes", "rays", "update ms", "raycast ms", "hits", "mismatch", "N_T/ray", "N_RB/ray", "N_TP/ray"});
    auto per_ray = [](std::uint64_t v, std::uint32_t rays) { return rays ? fixed(double(v) / rays, 1) : std::string("-"); };
    for (const FrameResult& f : res.frames) {
        t.add({std::to_string(f.frame) + (f.warmup ? "w" : ""), std::to_string(f.inserts + f.removes + f.moves),
               std::to_string(f.rays), fixed(f.update_ns / 1e6, 4), fixed(f.raycast_ns / 1e6, 3), std::to_string(f.hits),
               res.verified ? std::to_string(f.mismatches()) : "-", per_ray(f.counters.n_t, f.rays),
               per_ray(f.counters.n_rb, f.rays), per_ray(f.counters.n_tp, f.rays)});
    }
    const Spread u = res.update_ns(), c = res.raycast_ns();
    t.add({"median", "", "", fixed(u.median / 1e6, 4), fixed(c.median / 1e6, 3), "", "", "", "", ""});
    t.add({"MAD", "", "", fixed(u.mad / 1e6, 4), fixed(c.mad / 1e6, 3), "", "", "", "", ""});
    t.print(std::cout);
    if (!res.verified) {
        std::cout << "\nhits not verified (--no-verify)\n";
    } else if (res.mismatches() == 0) {
        std::cout << "\nhits verified against the double-precision ground truth: 0 mismatches\n";
    } else {
        std::cout << "\nMISMATCHES: " << res.mismatches() << " (first ones below)\n";
        static const char* kinds[] = {"missed", "extra", "duplicate"};
        for (const auto& [frame, d] : res.examples)
            std::cout << "  frame " << frame << " ray " << d.ray << " uid " << d.uid << ": " << kinds[d.kind] << '\n';
    }
}

}  // namespace

void add_simulate_command(CLI::App& app) {
    struct Options {
        std::string scene;
        StructureOptions structure;
        SimulationOptions sim;
        bool no_verify = false;
        bool no_count = false;
        bool json = false;
    };
    auto o = std::make_shared<Options>();
    CLI::App* cmd = app.add_subcommand("simulate", "Replay a recording against one structure: build, update and ray-cast "
                                                   "times per frame, verified against brute-force ground truth");
    cmd->add_option("--scene", o->scene, "Recording file (from rcbench scene gen/import)")->required();
    add_structure_options(*cmd, o->structure);
    cmd->add_option("--frames", o->sim.max_frames, "Replay at most this many frames (0: all)")->capture_default_str();
    cmd->add_option("--warmup", o->sim.warmup_frames, "Frames left out of the medians")->capture_default_str();
    cmd->add_flag("--no-verify", o->no_verify, "Skip the ground-truth comparison (faster on huge scenes)");
    cmd->add_flag("--no-count", o->no_count, "Skip the counting pass (N_T, N_RB, N_TP)");
    cmd->add_flag("--validate", o->sim.validate, "Check the structure's invariants after every frame");
    cmd->add_flag("--json", o->json, "Print one JSON object instead of the table");
    cmd->callback([o] {
        const Recording r = read_recording(o->scene);
        o->sim.verify = !o->no_verify;
        o->sim.count = !o->no_count;
        const StructureInfo& info = find_structure(o->structure.name);
        const SimulationResult res = simulate(r, info, o->structure.params(), o->sim, "--param");
        if (o->json) {
            nlohmann::json j = res.to_json();
            j["scene"] = o->scene;
            std::cout << j.dump() << '\n';
        } else {
            print_table(o->scene, res);
        }
        if (res.mismatches() > 0)
            throw std::runtime_error(std::to_string(res.mismatches()) + " hits disagree with the ground truth");
    });
}

}  // namespace rcb
