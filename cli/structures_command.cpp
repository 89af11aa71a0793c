// rcbench structures: what can be run, with every parameter's type, range and default.
#include <iostream>
#include <memory>

#include "accel/registry.h"
#include "cli/commands.h"
#include "cli/table.h"

namespace rcb {

void add_structures_command(CLI::App& app) {
    auto json = std::make_shared<bool>(false);
    CLI::App* cmd = app.add_subcommand("structures", "List the registered structures and their parameters");
    cmd->add_flag("--json", *json, "Print JSON");
    cmd->callback([json] {
        if (*json) {
            nlohmann::json all = nlohmann::json::array();
            for (const StructureInfo& s : structure_registry()) {
                nlohmann::json params = nlohmann::json::array();
                for (const ParamSpec& p : s.params) params.push_back(p.to_json());
                all.push_back({{"name", s.name}, {"summary", s.summary}, {"params", params}});
            }
            std::cout << all.dump(2) << '\n';
            return;
        }
        for (const StructureInfo& s : structure_registry()) {
            std::cout << s.name << ": " << s.summary << '\n';
            if (s.params.empty()) {
                std::cout << "  (no parameters)\n";
                continue;
            }
            TextTable t({"  parameter", "default", "expects", "tunable", "meaning"});
            for (const ParamSpec& p : s.params)
                t.add({"  " + p.name, p.default_value.dump(), p.expectation(), p.tunable ? "yes" : "no", p.doc});
            t.print(std::cout);
        }
    });
}

}  // namespace rcb
