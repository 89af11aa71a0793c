#pragma once
/// Structures by name (pbrt-style: one factory by name, unknown names and parameters reported).
/// A new structure adds one line to registry.cpp and nothing else.

#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/params.h"
#include "core/structure.h"

namespace rcb {

struct StructureInfo {
    std::string name;
    std::string summary;
    std::vector<ParamSpec> params;
    /// Makes the structure from a parameter object (defaults for missing keys); `path` prefixes
    /// error messages, e.g. "structures[2].params" or "--param".
    std::function<std::unique_ptr<Structure>(const nlohmann::json& params, const std::string& path)> make;

    /// Every parameter at its default.
    nlohmann::json defaults() const;
    /// `params` completed with the defaults (what a result records), after validation.
    nlohmann::json complete(const nlohmann::json& params, const std::string& path) const;
};

/// Every registered structure, in registration order.
const std::vector<StructureInfo>& structure_registry();
/// Throws InputError "unknown structure 'x' (known: bf, ug, …)".
const StructureInfo& find_structure(std::string_view name);

/// The registry entry of a structure type S with a nested `Params` and a constructor from it.
template <class S>
StructureInfo describe_structure(std::string name, std::string summary) {
    StructureInfo info;
    info.name = name;
    info.summary = std::move(summary);
    info.params = param_specs<typename S::Params>();
    info.make = [name](const nlohmann::json& params, const std::string& path) -> std::unique_ptr<Structure> {
        return std::make_unique<S>(params_from_json<typename S::Params>(params, path, name));
    };
    return info;
}

}  // namespace rcb
