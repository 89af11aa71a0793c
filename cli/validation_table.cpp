#include "cli/validation_table.h"

#include <cmath>
#include <map>
#include <utility>

namespace rcb {
namespace {

/// "12.3% [8.1, 17.0]": a value with its bootstrap interval, in percent.
std::string with_interval(double v, double low, double high) {
    std::string text = percent(v);
    if (std::isfinite(v) && std::isfinite(low)) text += " [" + fixed(100 * low, 1) + ", " + fixed(100 * high, 1) + "]";
    return text;
}

/// "eq5.4 x5, per-category x1": how many splits chose each form.
std::string forms_text(const std::map<std::string, int>& forms) {
    std::string text;
    for (const auto& [form, n] : forms) text += (text.empty() ? "" : ", ") + form + " x" + std::to_string(n);
    return text.empty() ? "-" : text;
}

}  // namespace

std::string percent(double v) { return std::isfinite(v) ? fixed(100 * v, 1) + "%" : "-"; }

TextTable validation_table(const ValidationGroup& group, const std::string& indent) {
    TextTable t({indent + "structure", "cells", "scenes", "frame median", "frame p90", "ray cast median",
                 "ray cast p90", "unpredictable", "outside range", "ray-cast forms chosen"});
    for (const StructureValidation& s : group.structures)
        t.add({indent + s.structure, std::to_string(s.cells), std::to_string(s.scenes),
               with_interval(s.frame.median, s.frame.median_low, s.frame.median_high),
               with_interval(s.frame.p90, s.frame.p90_low, s.frame.p90_high),
               with_interval(s.raycast.median, s.raycast.median_low, s.raycast.median_high),
               with_interval(s.raycast.p90, s.raycast.p90_low, s.raycast.p90_high), std::to_string(s.unpredictable),
               std::to_string(s.outside), forms_text(s.raycast_models)});
    return t;
}

TextTable kind_validation_table(const std::vector<ValidationGroup>& groups, const std::string& indent) {
    TextTable t({indent + "structure", "kind", "cells", "scenes", "ray cast median", "ray cast p90", "unpredictable"});
    std::map<std::string, std::vector<std::pair<std::string, const StructureValidation*>>> rows;  // by structure
    for (const ValidationGroup& g : groups) {
        const std::string kind = g.name.substr(g.name.find(':') + 1);
        for (const StructureValidation& s : g.structures) rows[s.structure].emplace_back(kind, &s);
    }
    for (const auto& [structure, kinds] : rows)
        for (const auto& [kind, s] : kinds)
            t.add({indent + structure, kind, std::to_string(s->cells), std::to_string(s->scenes),
                   with_interval(s->raycast.median, s->raycast.median_low, s->raycast.median_high),
                   with_interval(s->raycast.p90, s->raycast.p90_low, s->raycast.p90_high),
                   std::to_string(s->unpredictable)});
    return t;
}

}  // namespace rcb
