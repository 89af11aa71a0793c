#include "cli/run_ref.h"

#include <charconv>
#include <filesystem>

#include <nlohmann/json.hpp>

#include "analysis/cost_model.h"
#include "runner/results_reader.h"

namespace rcb {

RunRef parse_run_ref(const std::string& option, const std::string& text) {
    RunRef r{option, text, text, 0};
    const std::size_t colon = text.rfind(':');
    if (colon != std::string::npos && colon + 1 < text.size() &&
        text.find_first_not_of("0123456789", colon + 1) == std::string::npos) {
        r.path = text.substr(0, colon);
        const auto [end, ec] = std::from_chars(text.data() + colon + 1, text.data() + text.size(), r.run);
        if (ec != std::errc() || r.run < 1) throw InputError(option + " " + text + ": a run id is a whole number >= 1");
    }
    if (!std::filesystem::is_regular_file(r.path))
        throw InputError(option + " " + text + ": no such results database " + r.path);
    return r;
}

std::int64_t resolve_ref(Database& db, const RunRef& ref) {
    return naming(ref, [&] {
        if (ref.run) {
            if (!run_exists(db, ref.run)) throw InputError("no run " + std::to_string(ref.run) + " in " + ref.path);
        }
        return resolve_run(db, ref.run, "");
    });
}

std::string run_cache(Database& db, std::int64_t run) {
    const std::optional<std::string> content = read_experiment_content(db, run);
    if (!content) return "warm";
    const nlohmann::json j = nlohmann::json::parse(*content, nullptr, false);
    return j.is_object() && j.value("cache", "") == "cold" ? "cold" : "warm";
}

void note_cache_difference(const std::string& cache_a, const std::string& name_a, const std::string& cache_b,
                           const std::string& name_b, std::ostream& err) {
    if (cache_a == cache_b) return;
    err << "note: " << name_a << " ran with a " << cache_a << " cache and " << name_b << " with a " << cache_b
        << " one (the experiment's \"cache\"): their update times measure different states\n";
}

}  // namespace rcb
