#include "core/base/json_input.h"

#include <string>
#include <vector>

#include "core/base/error.h"

namespace rcb {

using json = nlohmann::json;

namespace {

/// Where the parser is: one step per open object or array (its last key, or its element index), so
/// that a refusal can name the JSON path that nests too deep.
class ParsePath {
public:
    void open(bool array) {
        enter_element();
        steps_.push_back({array, -1, ""});
    }
    void close() {
        if (!steps_.empty()) steps_.pop_back();
    }
    void key(const std::string& k) {
        if (!steps_.empty()) steps_.back().key = k;
    }
    void value() { enter_element(); }
    /// The first few steps (a nest of thousands would make a line of thousands): "a.b[3][0]...".
    std::string text(std::size_t max_steps = 8) const {
        std::string out;
        for (std::size_t i = 0; i + 1 < steps_.size() && i < max_steps; ++i) {
            const Step& s = steps_[i];
            if (s.array) {
                out.append("[").append(std::to_string(s.index)).append("]");
            } else {
                if (!out.empty()) out.append(".");
                out.append(s.key);
            }
        }
        if (steps_.size() > max_steps + 1) out += "...";
        return out;
    }

private:
    struct Step {
        bool array;
        long index;
        std::string key;
    };
    void enter_element() {
        if (!steps_.empty() && steps_.back().array) ++steps_.back().index;
    }
    std::vector<Step> steps_;
};

}  // namespace

nlohmann::json parse_json_document(const std::string& text, const std::string& name) {
    // The parser callback sees each value's depth as it is opened, before anything nested deeper
    // is built, so a 50 000-level document is refused at level 65, naming the path to it.
    ParsePath path;
    auto limit_depth = [&](int depth, json::parse_event_t event, json& parsed) {
        switch (event) {
            case json::parse_event_t::object_start:
            case json::parse_event_t::array_start:
                path.open(event == json::parse_event_t::array_start);
                if (depth >= kMaxJsonDepth)
                    throw InputError(name + ": " + path.text() + ": JSON nests deeper than " +
                                     std::to_string(kMaxJsonDepth) + " levels");
                break;
            case json::parse_event_t::object_end:
            case json::parse_event_t::array_end:
                path.close();
                break;
            case json::parse_event_t::key:
                path.key(parsed.get<std::string>());
                break;
            case json::parse_event_t::value:
                path.value();
                break;
        }
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
