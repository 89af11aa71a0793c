#include "core/scene/import/nesting.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <filesystem>
#include <unordered_map>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/base/error.h"
#include "core/scene/scene.h"

namespace rcb {
namespace {

std::string limit_text() { return std::to_string(kMaxModelNesting) + " (kMaxModelNesting, nesting.h)"; }

/// "byte 1234, line 56" of an offset into the text (lines counted only when reporting).
std::string position(std::string_view text, std::size_t offset) {
    offset = std::min(offset, text.size());
    const auto lines = std::count(text.begin(), text.begin() + std::ptrdiff_t(offset), '\n');
    return "byte " + std::to_string(offset) + ", line " + std::to_string(lines + 1);
}

[[noreturn]] void too_deep(const std::string& name, const char* what, std::string_view text, std::size_t offset) {
    throw InputError(name + ": " + what + " nested deeper than " + limit_text() + " at " + position(text, offset) +
                     "; assimp's parser recurses once per level");
}

/// Depth of { } and [ ] outside double-quoted strings (with backslash escapes): JSON exactly, and
/// the brace-structured text formats (FBX ASCII, DirectX .x) closely enough to bound them. A
/// stray closing bracket does not go below zero.
void check_brackets(std::string_view t, const std::string& name, const char* what) {
    std::size_t depth = 0;
    bool in_string = false;
    for (std::size_t i = 0; i < t.size(); ++i) {
        const char c = t[i];
        if (in_string) {
            if (c == '\\')
                ++i;
            else if (c == '"')
                in_string = false;
        } else if (c == '"') {
            in_string = true;
        } else if (c == '{' || c == '[') {
            if (++depth > kMaxModelNesting) too_deep(name, what, t, i);
        } else if ((c == '}' || c == ']') && depth > 0) {
            --depth;
        }
    }
}

/// One start tag of an XML document: its name and the text of its attributes.
struct Tag {
    std::string_view name, attributes;
    std::size_t offset = 0;
};

/// The value of attribute `key` in a start tag's attribute text ("" when absent).
std::string_view attribute(std::string_view attrs, std::string_view key) {
    std::size_t i = 0;
    while (i < attrs.size()) {
        while (i < attrs.size() && std::isspace(static_cast<unsigned char>(attrs[i]))) ++i;
        const std::size_t name_start = i;
        while (i < attrs.size() && attrs[i] != '=' && !std::isspace(static_cast<unsigned char>(attrs[i]))) ++i;
        const std::string_view name = attrs.substr(name_start, i - name_start);
        while (i < attrs.size() && (attrs[i] == '=' || std::isspace(static_cast<unsigned char>(attrs[i])))) ++i;
        if (i >= attrs.size() || (attrs[i] != '"' && attrs[i] != '\'')) return {};
        const char quote = attrs[i++];
        const std::size_t end = attrs.find(quote, i);
        if (end == std::string_view::npos) return {};
        if (name == key) return attrs.substr(i, end - i);
        i = end + 1;
        if (name.empty()) return {};
    }
    return {};
}

/// Walks an XML document's elements without building it: `open(tag, depth)` for every start tag
/// (self-closing ones too, with `self_closing` set), `close()` for every end of a non-self-closing
/// element. Comments, CDATA, processing instructions and declarations are skipped; quoted
/// attribute values may hold '>'. Throws when elements nest deeper than the limit.
template <class Open, class Close>
void walk_xml(std::string_view t, const std::string& name, Open&& open, Close&& close) {
    std::size_t depth = 0, i = 0;
    auto skip_past = [&](std::size_t from, std::string_view end) {
        const std::size_t j = t.find(end, from);
        return j == std::string_view::npos ? t.size() : j + end.size();
    };
    while ((i = t.find('<', i)) != std::string_view::npos) {
        const std::string_view rest = t.substr(i);
        if (rest.substr(0, 4) == "<!--") {
            i = skip_past(i + 4, "-->");
            continue;
        }
        if (rest.substr(0, 9) == "<![CDATA[") {
            i = skip_past(i + 9, "]]>");
            continue;
        }
        if (rest.substr(0, 2) == "<?") {
            i = skip_past(i + 2, "?>");
            continue;
        }
        if (rest.substr(0, 2) == "<!") {  // <!DOCTYPE ...>, possibly with an internal subset [ ... ]
            const std::size_t gt = t.find('>', i), bracket = t.find('[', i);
            i = bracket < gt ? skip_past(skip_past(bracket, "]"), ">") : skip_past(i, ">");
            continue;
        }
        if (rest.substr(0, 2) == "</") {
            if (depth > 0) {
                --depth;
                close();
            }
            i = skip_past(i + 2, ">");
            continue;
        }
        // A start tag: its name, then attributes up to the '>' outside quotes.
        std::size_t j = i + 1;
        while (j < t.size() && !std::isspace(static_cast<unsigned char>(t[j])) && t[j] != '>' && t[j] != '/') ++j;
        const std::string_view tag_name = t.substr(i + 1, j - i - 1);
        const std::size_t attrs_start = j;
        char quote = 0;
        for (; j < t.size(); ++j) {
            if (quote) {
                if (t[j] == quote) quote = 0;
            } else if (t[j] == '"' || t[j] == '\'') {
                quote = t[j];
            } else if (t[j] == '>') {
                break;
            }
        }
        const bool self_closing = j > attrs_start && j < t.size() && t[j - 1] == '/';
        const std::string_view attrs = t.substr(attrs_start, j - attrs_start - (self_closing ? 1 : 0));
        if (!self_closing && ++depth > kMaxModelNesting) too_deep(name, "XML elements", t, i);
        open(Tag{tag_name, attrs, i}, self_closing);
        i = j + 1;
    }
}

void check_xml(std::string_view t, const std::string& name) {
    walk_xml(
        t, name, [](const Tag&, bool) {}, [] {});
}

/// COLLADA: the graph of <node> elements, their child nodes, and the nodes their <instance_node
/// url="#id"> elements instantiate (assimp resolves a url by the node's id, else by its name, and
/// copies the instantiated node's subtree in place). No cycle; the expanded hierarchy no deeper
/// than the limit and no larger than kMaxSceneObjects nodes.
void check_collada(std::string_view t, const std::string& name) {
    struct Node {
        std::string_view id, name;
        std::size_t offset;
        std::vector<std::size_t> children;        // nested <node> elements
        std::vector<std::string_view> instances;  // <instance_node> urls, without '#'
    };
    std::vector<Node> nodes;
    std::vector<std::size_t> roots;          // the top nodes of visual scenes: what assimp builds
    std::vector<std::ptrdiff_t> open_nodes;  // per open element: its node index, or -1
    std::size_t in_visual_scene = 0;         // open <visual_scene> elements
    std::vector<bool> open_scene;            // per open element: is it a <visual_scene>
    walk_xml(
        t, name,
        [&](const Tag& tag, bool self_closing) {
            std::ptrdiff_t parent = -1;
            for (auto it = open_nodes.rbegin(); it != open_nodes.rend(); ++it)
                if (*it >= 0) {
                    parent = *it;
                    break;
                }
            const bool scene = tag.name == "visual_scene";
            if (tag.name == "node") {
                nodes.push_back(
                    {attribute(tag.attributes, "id"), attribute(tag.attributes, "name"), tag.offset, {}, {}});
                const std::size_t index = nodes.size() - 1;
                if (parent >= 0)
                    nodes[std::size_t(parent)].children.push_back(index);
                else if (in_visual_scene > 0)
                    roots.push_back(index);
                if (!self_closing) open_nodes.push_back(std::ptrdiff_t(index)), open_scene.push_back(false);
                return;
            }
            if (tag.name == "instance_node" && parent >= 0) {
                std::string_view url = attribute(tag.attributes, "url");
                if (!url.empty() && url.front() == '#') url.remove_prefix(1);
                nodes[std::size_t(parent)].instances.push_back(url);
            }
            if (!self_closing) {
                open_nodes.push_back(-1), open_scene.push_back(scene);
                in_visual_scene += scene;
            }
        },
        [&] {
            if (open_nodes.empty()) return;
            open_nodes.pop_back();
            in_visual_scene -= open_scene.back();
            open_scene.pop_back();
        });
    if (nodes.empty()) return;
    std::unordered_map<std::string_view, std::size_t> by_id, by_name;
    for (std::size_t i = 0; i < nodes.size(); ++i) {
        if (!nodes[i].id.empty()) by_id.emplace(nodes[i].id, i);
        if (!nodes[i].name.empty()) by_name.emplace(nodes[i].name, i);
    }
    // Iterative depth-first search over child and instance edges: colour 1 = on the path (a cycle
    // when met again), 2 = done, with the subtree's expanded size and depth.
    std::vector<std::uint8_t> colour(nodes.size(), 0);
    std::vector<std::uint64_t> size(nodes.size(), 1);
    std::vector<std::size_t> depth(nodes.size(), 1);
    auto edges = [&](std::size_t n) {
        std::vector<std::size_t> out = nodes[n].children;
        for (std::string_view url : nodes[n].instances)
            if (auto it = by_id.find(url); it != by_id.end())
                out.push_back(it->second);
            else if (auto named = by_name.find(url); named != by_name.end())
                out.push_back(named->second);
        return out;
    };
    const std::uint64_t cap = kMaxSceneObjects + 1;  // sizes saturate here
    for (std::size_t start = 0; start < nodes.size(); ++start) {
        if (colour[start]) continue;
        struct Frame {
            std::size_t node;
            std::vector<std::size_t> next;
            std::size_t at = 0;
        };
        std::vector<Frame> stack;
        stack.push_back({start, edges(start)});
        colour[start] = 1;
        while (!stack.empty()) {
            Frame& f = stack.back();
            if (f.at < f.next.size()) {
                const std::size_t c = f.next[f.at++];
                if (colour[c] == 1)
                    throw InputError(name + ": COLLADA node " + quoted_excerpt(nodes[c].id) + " at " +
                                     position(t, nodes[c].offset) +
                                     " contains itself through <instance_node> (a cycle)");
                if (colour[c] == 0) {
                    colour[c] = 1;
                    stack.push_back({c, edges(c)});
                }
                continue;
            }
            const std::size_t n = f.node;
            for (std::size_t c : f.next) {
                size[n] = std::min(cap, size[n] + size[c]);
                depth[n] = std::max(depth[n], depth[c] + 1);
            }
            colour[n] = 2;
            stack.pop_back();
            if (depth[n] > kMaxModelNesting)
                throw InputError(name + ": COLLADA node " + quoted_excerpt(nodes[n].id) + " at " +
                                 position(t, nodes[n].offset) + " expands to a hierarchy deeper than " + limit_text());
        }
    }
    std::uint64_t total = 0;
    for (std::size_t r : roots) total = std::min(cap, total + size[r]);
    if (total > kMaxSceneObjects)
        throw InputError(name + ": the COLLADA node graph expands to more than " + std::to_string(kMaxSceneObjects) +
                         " nodes through <instance_node> (the limit of objects per scene, kMaxSceneObjects, scene.h)");
}

/// glTF: JSON depth, then the node hierarchy. glTF 2.0 lists nodes in an array and children by
/// index; glTF 1.0 (still read by assimp) keeps them in an object and children by id.
void check_gltf_json(std::string_view text, const std::string& name) {
    check_brackets(text, name, "JSON arrays and objects");
    nlohmann::json doc;
    try {
        doc = nlohmann::json::parse(text.begin(), text.end());
    } catch (const nlohmann::json::exception&) {
        return;  // not JSON: assimp reports what is wrong
    }
    if (!doc.is_object() || !doc.contains("nodes")) return;
    const nlohmann::json& nodes = doc["nodes"];
    std::vector<const nlohmann::json*> node;
    std::vector<std::string> label;
    std::unordered_map<std::string, std::size_t> by_id;
    if (nodes.is_array()) {
        for (std::size_t i = 0; i < nodes.size(); ++i) node.push_back(&nodes[i]), label.push_back(std::to_string(i));
    } else if (nodes.is_object()) {
        for (const auto& [key, value] : nodes.items()) {
            by_id.emplace(key, node.size());
            node.push_back(&value);
            label.push_back(quoted_excerpt(key));
        }
    } else {
        return;
    }
    auto child_index = [&](const nlohmann::json& c) -> std::ptrdiff_t {
        if (c.is_number_unsigned() && c.get<std::uint64_t>() < node.size())
            return std::ptrdiff_t(c.get<std::uint64_t>());
        if (c.is_string())
            if (auto it = by_id.find(c.get<std::string>()); it != by_id.end()) return std::ptrdiff_t(it->second);
        return -1;  // a dangling reference: assimp reports it
    };
    std::vector<std::ptrdiff_t> parent(node.size(), -1);
    std::vector<std::vector<std::size_t>> children(node.size());
    for (std::size_t n = 0; n < node.size(); ++n) {
        if (!node[n]->is_object() || !node[n]->contains("children") || !(*node[n])["children"].is_array()) continue;
        for (const nlohmann::json& c : (*node[n])["children"]) {
            const std::ptrdiff_t k = child_index(c);
            if (k < 0) continue;
            if (std::size_t(k) == n) throw InputError(name + ": glTF node " + label[n] + " is its own child (a cycle)");
            if (parent[std::size_t(k)] == std::ptrdiff_t(n))
                throw InputError(name + ": glTF node " + label[std::size_t(k)] +
                                 " is listed twice among the children of node " + label[n] +
                                 " (glTF node hierarchies are strict trees)");
            if (parent[std::size_t(k)] >= 0)
                throw InputError(name + ": glTF node " + label[std::size_t(k)] + " is a child of both node " +
                                 label[std::size_t(parent[std::size_t(k)])] + " and node " + label[n] +
                                 " (glTF node hierarchies are strict trees)");
            parent[std::size_t(k)] = std::ptrdiff_t(n);
            children[n].push_back(std::size_t(k));
        }
    }
    // With one parent per node, the hierarchy is a forest plus possibly cycles without a root.
    std::vector<std::size_t> depth(node.size(), 0), order;
    std::vector<std::size_t> stack;
    for (std::size_t n = 0; n < node.size(); ++n)
        if (parent[n] < 0) {
            depth[n] = 1;
            stack.push_back(n);
        }
    while (!stack.empty()) {
        const std::size_t n = stack.back();
        stack.pop_back();
        order.push_back(n);
        if (depth[n] > kMaxModelNesting)
            throw InputError(name + ": glTF node " + label[n] + " is nested deeper than " + limit_text() +
                             " through \"children\"; assimp recurses once per level");
        for (std::size_t c : children[n]) {
            depth[c] = depth[n] + 1;
            stack.push_back(c);
        }
    }
    if (order.size() < node.size()) {
        for (std::size_t n = 0; n < node.size(); ++n)
            if (depth[n] == 0)
                throw InputError(name + ": glTF node " + label[n] +
                                 " is its own ancestor through \"children\" (a cycle)");
    }
    // assimp copies a node's subtree for every time a scene lists it as a root: the sum over the
    // scenes' root lists of subtree sizes is the size of the tree it builds.
    std::vector<std::uint64_t> size(node.size(), 1);
    for (auto it = order.rbegin(); it != order.rend(); ++it)
        if (parent[*it] >= 0) size[std::size_t(parent[*it])] += size[*it];
    std::uint64_t total = 0;
    auto add_roots = [&](const nlohmann::json& scene) {
        if (!scene.is_object() || !scene.contains("nodes") || !scene["nodes"].is_array()) return;
        for (const nlohmann::json& r : scene["nodes"])
            if (const std::ptrdiff_t k = child_index(r); k >= 0) total += size[std::size_t(k)];
    };
    if (doc.contains("scenes")) {
        if (doc["scenes"].is_array())
            for (const nlohmann::json& scene : doc["scenes"]) add_roots(scene);
        else if (doc["scenes"].is_object())
            for (const auto& [key, scene] : doc["scenes"].items()) add_roots(scene);
    }
    if (total > kMaxSceneObjects)
        throw InputError(name + ": the glTF scenes list node subtrees of " + std::to_string(total) +
                         " nodes in all, more than the limit of " + std::to_string(kMaxSceneObjects) +
                         " objects per scene (kMaxSceneObjects, scene.h)");
}

/// The JSON of a binary glTF: glTF 2.0's first chunk (type "JSON"), or glTF 1.0's content.
void check_glb(std::string_view b, const std::string& name) {
    auto u32 = [&](std::size_t at) {
        std::uint32_t v = 0;
        for (int k = 0; k < 4; ++k) v |= std::uint32_t(static_cast<unsigned char>(b[at + k])) << (8 * k);
        return v;
    };
    if (b.size() < 20 || b.substr(0, 4) != "glTF") return;  // not a binary glTF: assimp reports it
    const std::uint32_t version = u32(4);
    std::size_t at = 0, length = 0;
    if (version == 2 && u32(16) == 0x4E4F534Au)
        at = 20, length = u32(12);
    else if (version == 1 && u32(16) == 0)
        at = 20, length = u32(12);
    else
        return;
    if (length > b.size() - at) length = b.size() - at;
    check_gltf_json(b.substr(at, length), name);
}

bool looks_like_text(std::string_view b) {
    const std::string_view head = b.substr(0, 4096);
    return head.find('\0') == std::string_view::npos;
}

/// The file's bytes, mapped read-only (not copied: model files can be large).
class MappedFile {
public:
    explicit MappedFile(const std::string& path) {
        const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
        if (fd < 0) return;  // assimp reports a file it cannot open
        struct stat st {};
        if (::fstat(fd, &st) == 0 && S_ISREG(st.st_mode) && st.st_size > 0) {
            void* p = ::mmap(nullptr, std::size_t(st.st_size), PROT_READ, MAP_PRIVATE, fd, 0);
            if (p != MAP_FAILED) data_ = static_cast<const char*>(p), size_ = std::size_t(st.st_size);
        }
        ::close(fd);
    }
    ~MappedFile() {
        if (data_) ::munmap(const_cast<char*>(data_), size_);
    }
    MappedFile(const MappedFile&) = delete;
    MappedFile& operator=(const MappedFile&) = delete;
    std::string_view bytes() const { return {data_, size_}; }

private:
    const char* data_ = nullptr;
    std::size_t size_ = 0;
};

}  // namespace

void check_model_nesting_text(std::string_view b, const std::string& name, const std::string& kind) {
    if (kind == "gltf") return check_gltf_json(b, name);
    if (kind == "glb") return check_glb(b, name);
    if (kind == "dae") return check_collada(b, name);
    if (b.substr(0, 4) == "glTF") return check_glb(b, name);
    if (!looks_like_text(b)) return;
    std::string_view text = b;
    if (text.substr(0, 3) == "\xEF\xBB\xBF") text.remove_prefix(3);
    const std::size_t first = text.find_first_not_of(" \t\r\n");
    if (first != std::string_view::npos && text[first] == '<') return check_xml(b, name);
    check_brackets(b, name, "brackets ({ } or [ ])");
}

void check_model_nesting(const std::string& path) {
    std::string ext = std::filesystem::path(path).extension().string();
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    const std::string kind = ext == ".gltf" ? "gltf" : ext == ".glb" ? "glb" : ext == ".dae" ? "dae" : "";
    const MappedFile file(path);
    check_model_nesting_text(file.bytes(), path, kind);
}

}  // namespace rcb
