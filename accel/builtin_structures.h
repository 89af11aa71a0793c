#pragma once
/// Which registered structures are rcbench's own: the entries the registry starts with, before any
/// program adds its own with register_structure (registry.h). The calibration pass gives a budget
/// to the others only (runner/calibration.h).

#include <string_view>

namespace rcb {

/// Whether `name` is one of rcbench's own structures, not one a program added with register_structure.
bool rcbench_structure(std::string_view name);

}  // namespace rcb
