// rcbench simulate: one structure over one recording, as a table (thesis Tables 6.1/6.2) or JSON.
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>

#include "core/scene/recording_io.h"
#include "sim/simulator.h"
#include "cli/cli_checks.h"
#include "cli/commands.h"
#include "core/base/error.h"
#include "core/base/output_file.h"
#include "cli/table.h"
#include "runner/calibration.h"

namespace rcb {
namespace {

void print_table(const std::string& scene, const SimulationResult& res) {
    std::cout << "scene      " << scene << " (" << res.objects << " objects, " << res.frames.size() << " frames)\n"
              << "structure  " << res.structure << ' ' << res.params.dump() << '\n'
              << "build      " << fixed(res.build_ns / 1e6, 3) << " ms   memory "
              << bytes_text(double(res.memory_bytes)) << " ("
              << fixed(res.objects ? double(res.memory_bytes) / double(res.objects) : 0.0, 1) << " B/object)\n\n";
    TextTable t(
        {"frame", "changes", "rays", "update ms", "raycast ms", "hits", "mismatch", "N_T/ray", "N_RB/ray", "N_TP/ray"});
    auto per_ray = [](std::uint64_t v, std::uint32_t rays) {
        return rays ? fixed(double(v) / rays, 1) : std::string("-");
    };
    for (const FrameResult& f : res.frames) {
        t.add({std::to_string(f.frame) + (f.warmup ? "w" : ""), std::to_string(f.inserts + f.removes + f.moves),
               std::to_string(f.rays), fixed(f.update_ns / 1e6, 4), fixed(f.raycast_ns / 1e6, 3),
               std::to_string(f.hits), res.verified ? std::to_string(f.mismatches()) : "-",
               per_ray(f.counters.n_t, f.rays), per_ray(f.counters.n_rb, f.rays), per_ray(f.counters.n_tp, f.rays)});
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

/// Thesis Tables 6.1 and 6.2: structures × scenes, build ms; ray-cast ms per frame (update ms).
void print_grid(const std::vector<std::string>& scenes, const std::vector<std::vector<SimulationResult>>& results) {
    std::vector<std::string> header{"build ms"};
    for (const std::string& s : scenes) header.push_back(std::filesystem::path(s).stem().string());
    TextTable build(header);
    header[0] = "ray cast ms (update ms)";
    TextTable cast(header);
    header[0] = "memory B/object";
    TextTable memory(header);
    header[0] = "mismatches";
    TextTable wrong(header);
    for (std::size_t k = 0; k < results.front().size(); ++k) {
        const std::string name = results.front()[k].structure;
        std::vector<std::string> b{name}, c{name}, m{name}, w{name};
        for (const auto& per_scene : results) {
            const SimulationResult& r = per_scene[k];
            b.push_back(fixed(r.build_ns / 1e6, 3));
            c.push_back(fixed(r.raycast_ns().median / 1e6, 3) + " (" + fixed(r.update_ns().median / 1e6, 4) + ")");
            m.push_back(fixed(r.objects ? double(r.memory_bytes) / double(r.objects) : 0.0, 1));
            w.push_back(r.verified ? std::to_string(r.mismatches()) : "-");
        }
        build.add(b), cast.add(c), memory.add(m), wrong.add(w);
    }
    std::cout << "Medians over frames; ray cast is the frame's whole batch of rays.\n\n";
    build.print(std::cout);
    std::cout << '\n';
    cast.print(std::cout);
    std::cout << '\n';
    memory.print(std::cout);
    std::cout << '\n';
    wrong.print(std::cout);
}

}  // namespace

void add_simulate_command(CLI::App& app) {
    struct Options {
        std::vector<std::string> scenes;
        std::vector<std::string> structures;
        std::vector<std::string> params_text;
        SimulationOptions sim;
        bool no_verify = false;
        bool no_count = false;
        bool json = false;
        std::string json_out;
        std::string cache = "warm";
    };
    auto o = std::make_shared<Options>();
    CLI::App* cmd =
        app.add_subcommand("simulate",
                           "Replay recordings against structures: times per frame, checked against ground truth\n"
                           "Replay recordings against structures: build, update and ray-cast times per "
                           "frame, verified against brute-force "
                           "ground truth. One scene and one structure: a per-frame table; several: the "
                           "thesis' Tables 6.1/6.2 (structures x scenes)");
    cmd->add_option("--scene", o->scenes, "Recording file (from rcbench scene gen/import); repeatable")
        ->required()
        ->check(input_file());
    cmd->add_option("--structure", o->structures, "Structure name (rcbench structures lists them), or all; repeatable")
        ->required();
    cmd->add_option("--param", o->params_text, "Structure parameter key=value (repeatable; with one --structure only)");
    cmd->add_option("--frames", o->sim.max_frames, "Replay at most this many frames (0: all)")
        ->capture_default_str()
        ->check(whole_number(0, 1'000'000));
    cmd->add_option("--warmup", o->sim.warmup_frames, "Frames left out of the medians")
        ->capture_default_str()
        ->check(whole_number(0, 1'000'000));
    cmd->add_flag("--no-verify", o->no_verify, "Skip the ground-truth comparison (faster on huge scenes)");
    cmd->add_flag("--no-count", o->no_count, "Skip the counting pass (N_T, N_RB, N_TP)");
    cmd->add_flag("--check", o->sim.check, "Check the structure's invariants after the build and every frame");
    add_deprecated_alias(cmd, "--validate", "--check", o->sim.check);
    cmd->add_option("--cache", o->cache,
                    "warm: each phase meets the caches as the last left them (the thesis' loop); cold: before each "
                    "frame's update, read a buffer twice the largest cache, so update and ray cast start cold "
                    "(docs/model.md, \"A cold cache before each update\")")
        ->capture_default_str()
        ->check(CLI::IsMember({"warm", "cold"}));
    cmd->add_flag("--json", o->json, "Print one JSON object per run (one line each) instead of tables");
    cmd->add_option("--json-out", o->json_out, "Also write one JSON object per run (one line each) to this file");
    cmd->callback([o] {
        if (!o->params_text.empty() && o->structures.size() != 1)
            throw InputError("--param needs exactly one --structure (got " + std::to_string(o->structures.size()) +
                             ")");
        o->sim.verify = !o->no_verify;
        o->sim.count = !o->no_count;
        if (o->cache == "cold") o->sim.cold_cache = std::make_shared<const CacheSweep>(cold_sweep_bytes());
        nlohmann::json params = nlohmann::json::object();
        for (const std::string& kv : o->params_text) {
            auto [key, value] = parse_key_value(kv);
            params[key] = value;
        }
        // "all" is every registered structure; every name is looked up before the first (possibly long) run.
        std::vector<std::string> names;
        for (const std::string& name : o->structures) {
            if (name == "all") {
                for (const StructureInfo& info : structure_registry()) names.push_back(info.name);
            } else {
                names.push_back(find_structure(name).name);
            }
        }
        o->structures = names;
        if (!o->json_out.empty()) check_output_path(o->json_out, o->scenes, "--json-out");
        std::string json_lines;  // written whole at the end: a failed run leaves the file as it was
        std::vector<std::vector<SimulationResult>> results;
        std::uint64_t mismatches = 0;
        for (const std::string& scene : o->scenes) {
            const Recording r = read_recording(scene);
            results.emplace_back();
            for (const std::string& name : o->structures) {
                SimulationResult res;
                try {
                    res = simulate(r, find_structure(name), params, o->sim, "--param");
                } catch (const InputError& e) {
                    throw InputError(scene + ": " + e.what());
                }
                mismatches += res.mismatches();
                nlohmann::json j = res.to_json();
                j["scene"] = scene;
                const std::string line = j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
                if (!o->json_out.empty()) json_lines += line + '\n';
                if (o->json) {
                    std::cout << line << std::endl;
                } else if (o->scenes.size() == 1 && o->structures.size() == 1) {
                    print_table(scene, res);
                }
                results.back().push_back(std::move(res));
            }
        }
        if (!o->json_out.empty()) write_file_atomically(o->json_out, json_lines);
        if (!o->json && (o->scenes.size() > 1 || o->structures.size() > 1)) print_grid(o->scenes, results);
        if (mismatches > 0)
            throw std::runtime_error(std::to_string(mismatches) + " hits disagree with the ground truth");
    });
}

}  // namespace rcb
