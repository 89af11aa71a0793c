#include "cli/validation_table.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <utility>

namespace rcb {
namespace {

/// A bound of an interval: "17.0", or "miss" where it reaches the misses.
std::string bound(double v) { return std::isinf(v) ? "miss" : fixed(100 * v, 1); }

/// "12.3% [8.1, 17.0]": a value with its bootstrap interval, in percent; "miss" where the
/// quantile falls on cells the model could not price.
std::string with_interval(double v, double low, double high) {
    std::string text = std::isinf(v) ? "miss" : percent(v);
    if (!std::isnan(v) && !std::isnan(low)) text += " [" + bound(low) + ", " + bound(high) + "]";
    return text;
}

/// "2 (8.3%)": the cells counted as misses and their share of the structure's cells.
std::string misses_text(std::size_t misses, std::size_t cells) {
    return cells ? std::to_string(misses) + " (" + fixed(100.0 * double(misses) / double(cells), 1) + "%)" : "0";
}

/// "eq5.4 x5, with-coherence x1": how many splits chose each form.
std::string forms_text(const std::map<std::string, int>& forms) {
    std::string text;
    for (const auto& [form, n] : forms) text += (text.empty() ? "" : ", ") + form + " x" + std::to_string(n);
    return text.empty() ? "-" : text;
}

}  // namespace

std::string percent(double v) { return std::isfinite(v) ? fixed(100 * v, 1) + "%" : "-"; }

TextTable validation_table(const ValidationGroup& group, const std::string& indent) {
    TextTable t({indent + "structure", "cells", "scenes", "frame median", "frame p90", "ray cast median",
                 "ray cast p90", "misses (share)", "outside range", "ray-cast forms chosen"});
    for (const StructureValidation& s : group.structures)
        t.add({indent + s.structure, std::to_string(s.cells), std::to_string(s.scenes),
               with_interval(s.frame.median, s.frame.median_low, s.frame.median_high),
               with_interval(s.frame.p90, s.frame.p90_low, s.frame.p90_high),
               with_interval(s.raycast.median, s.raycast.median_low, s.raycast.median_high),
               with_interval(s.raycast.p90, s.raycast.p90_low, s.raycast.p90_high), misses_text(s.misses, s.cells),
               std::to_string(s.outside), forms_text(s.raycast_models)});
    return t;
}

TextTable spread_table(const ValidationGroup& group, const std::vector<StructureNoise>& spread,
                       const std::string& indent) {
    TextTable t({indent + "structure", "frame median", "between runs median", "ratio", "frame p90", "between runs p90",
                 "ratio", "cells both runs hold"});
    const auto ratio = [](double error, double floor) {
        if (std::isinf(error)) return std::string("miss");
        return std::isfinite(error) && floor > 0 ? fixed(error / floor, 2) : std::string("-");
    };
    for (const StructureValidation& s : group.structures) {
        const auto n = std::find_if(spread.begin(), spread.end(),
                                    [&](const StructureNoise& x) { return x.structure == s.structure; });
        const double p50 = n == spread.end() ? NAN : n->frame, p90 = n == spread.end() ? NAN : n->frame_p90;
        t.add({indent + s.structure, with_interval(s.frame.median, NAN, NAN), percent(p50), ratio(s.frame.median, p50),
               with_interval(s.frame.p90, NAN, NAN), percent(p90), ratio(s.frame.p90, p90),
               n == spread.end() ? "0" : std::to_string(n->cells)});
    }
    return t;
}

TextTable kind_validation_table(const std::vector<ValidationGroup>& groups, const std::string& indent) {
    TextTable t(
        {indent + "structure", "query kind", "cells", "scenes", "ray cast median", "ray cast p90", "misses (share)"});
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
                   misses_text(s->misses, s->cells)});
    return t;
}

}  // namespace rcb
