#pragma once
/// The counters of eq. 5.4 by name (accel/model/counters.h holds them): the one list of them. The
/// name is the key of the simulator's JSON, the column of the database's frame and frame_kind
/// tables and the cost model's alias (analysis/model_terms.h frame_counters()), which all read it
/// from here. Beside counters.h rather than in it: the traversals, which include counters.h, need
/// no names.

#include <array>
#include <cstdint>
#include <string_view>

#include "accel/model/counters.h"

namespace rcb {

/// A counter's name and its member of Counters.
struct CounterField {
    const char* name;
    std::uint64_t Counters::*member;
};

inline constexpr std::array<CounterField, 9> kCounterFields{{{"n_t", &Counters::n_t},
                                                             {"n_th", &Counters::n_th},
                                                             {"n_rb", &Counters::n_rb},
                                                             {"n_tp", &Counters::n_tp},
                                                             {"n_dup", &Counters::n_dup},
                                                             {"n_ro", &Counters::n_ro},
                                                             {"n_ro_hits", &Counters::n_ro_hits},
                                                             {"n_mp", &Counters::n_mp},
                                                             {"n_miss", &Counters::n_miss}}};

/// The counter called `name`; nullptr for none.
constexpr const CounterField* counter_field(std::string_view name) {
    for (const CounterField& c : kCounterFields)
        if (name == c.name) return &c;
    return nullptr;
}

}  // namespace rcb
