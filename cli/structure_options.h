#pragma once
/// `--structure NAME [--param key=value]…`, shared by the commands that run one structure.

#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "accel/interface/params.h"

namespace rcb {

struct StructureOptions {
    std::string name;
    std::vector<std::string> params_text;

    /// The --param arguments as one JSON object (validated later against the registry).
    nlohmann::json params() const {
        nlohmann::json j = nlohmann::json::object();
        for (const std::string& kv : params_text) {
            auto [key, value] = parse_key_value(kv);
            j[key] = value;
        }
        return j;
    }
};

inline void add_structure_options(CLI::App& cmd, StructureOptions& o) {
    cmd.add_option("--structure", o.name, "Structure name (rcbench structures lists them)")->required();
    cmd.add_option("--param", o.params_text, "Structure parameter key=value (repeatable)");
}

}  // namespace rcb
