#pragma once
// A run named on the command line as "A.db" or "A.db:RUN" (validate's --train and --test, fit's
// --repeat), and its checks.
#include <cstdint>
#include <ostream>
#include <string>

#include "core/base/error.h"

namespace rcb {

class Database;

struct RunRef {
    std::string option, text, path;
    std::int64_t run = 0;  ///< 0: the newest run with cells
};

/// InputError "<option> <text>: …" for a run id that is not a whole number >= 1 or a path that is
/// not a file.
RunRef parse_run_ref(const std::string& option, const std::string& text);

/// `f()`, with any InputError it throws (not a database, unknown run, no frames) naming the option
/// and its value.
template <class F>
auto naming(const RunRef& ref, F f) {
    try {
        return f();
    } catch (const InputError& e) {
        throw InputError(ref.option + " " + ref.text + ": " + e.what());
    }
}

/// The run id `ref` names in `db` (its newest run with cells when it names none); InputError naming
/// the option when `db` has no such run.
std::int64_t resolve_ref(Database& db, const RunRef& ref);

/// The cache a run's updates met: "cold" when its experiment file says "cache": "cold"
/// (sim/cache_sweep.h), else "warm".
std::string run_cache(Database& db, std::int64_t run);

/// One line on `err` when two runs met different caches (run_cache): their times, the update's
/// most, measure different states, so an error between them is neither a model's nor a machine's.
void note_cache_difference(const std::string& cache_a, const std::string& name_a, const std::string& cache_b,
                           const std::string& name_b, std::ostream& err);

}  // namespace rcb
