#include "core/base/json_input.h"

#include "core/base/error.h"

namespace rcb {

using json = nlohmann::json;

nlohmann::json parse_json_document(const std::string& text, const std::string& name) {
    // The parser callback sees each value's depth as it is opened, before anything nested deeper
    // is built, so a 50 000-level document is refused at level 65.
    auto limit_depth = [&](int depth, json::parse_event_t event, json&) {
        if ((event == json::parse_event_t::object_start || event == json::parse_event_t::array_start) &&
            depth >= kMaxJsonDepth)
            throw InputError(name + ": JSON nests deeper than " + std::to_string(kMaxJsonDepth) + " levels");
        return true;
    };
    try {
        return json::parse(text, limit_depth);
    } catch (const json::exception& e) {  // parse_error, and out_of_range for a number like 1e999
        std::string what = e.what();
        if (what.size() > 200) what = what.substr(0, 197) + "...";
        throw InputError(name + ": not valid JSON (" + what + ")");
    }
}

std::string json_excerpt(const nlohmann::json& value, std::size_t max_chars) {
    std::string text;
    if (value.is_string() && value.get_ref<const std::string&>().size() > max_chars) {
        // Cut before dumping: a 5 MB string need not be escaped whole to show its start.
        text = json(value.get_ref<const std::string&>().substr(0, max_chars))
                   .dump(-1, ' ', false, json::error_handler_t::replace);
    } else {
        text = value.dump(-1, ' ', false, json::error_handler_t::replace);
    }
    if (text.size() > max_chars) text = text.substr(0, max_chars - 3) + "...";
    return text;
}

}  // namespace rcb
