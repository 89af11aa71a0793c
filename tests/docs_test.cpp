// The docs a newcomer reads against the binary they build: every command `rcbench --help` lists and
// every structure `rcbench structures` lists is named in README.md or docs/architecture.md, every
// command those docs name exists, and each command of the README's "Using it" block exists with the
// options it is given and the repository files it names.
#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>

#include "tests/subprocess.h"

namespace {

namespace fs = std::filesystem;

std::string read_source(const std::string& relative) {
    std::ifstream in(fs::path(RCBENCH_SOURCE_DIR) / relative);
    EXPECT_TRUE(in.good()) << relative;
    return std::string(std::istreambuf_iterator<char>(in), {});
}

std::string docs() { return read_source("README.md") + read_source("docs/architecture.md"); }

test::Outcome rcbench(const std::vector<std::string>& args) {
    std::vector<std::string> argv{RCBENCH_BINARY};
    argv.insert(argv.end(), args.begin(), args.end());
    test::RunOptions o;
    o.timeout_seconds = 120;
    return test::run_process(argv, o);
}

/// The subcommands a CLI11 help text lists: the names indented under "Subcommands:".
std::set<std::string> subcommands(const std::vector<std::string>& of) {
    std::vector<std::string> args = of;
    args.push_back("--help");
    const test::Outcome r = rcbench(args);
    EXPECT_EQ(r.code, 0) << r.err;
    std::set<std::string> names;
    std::istringstream lines(r.out.substr(std::min(r.out.size(), r.out.find("Subcommands:"))));
    std::string line;
    const std::regex entry(R"(^  ([a-z][a-z_-]*)\s)");
    std::smatch m;
    while (std::getline(lines, line))
        if (std::regex_search(line, m, entry)) names.insert(m[1]);
    return names;
}

/// True when `option` ("--json") is in `help` as a whole option name (not a prefix of "--json-out").
bool has_option(const std::string& help, const std::string& option) {
    for (std::size_t at = help.find(option); at != std::string::npos; at = help.find(option, at + 1)) {
        const std::size_t end = at + option.size();
        if (end == help.size() ||
            !(std::isalnum(static_cast<unsigned char>(help[end])) || help[end] == '-' || help[end] == '_'))
            return true;
    }
    return false;
}

/// The shell lines of the README's "Using it" section (its fenced block), comments removed.
std::vector<std::string> using_it_lines() {
    const std::string readme = read_source("README.md");
    const std::size_t section = readme.find("## Using it");
    EXPECT_NE(section, std::string::npos);
    const std::size_t open = readme.find("```sh\n", section);
    const std::size_t close = readme.find("\n```", open + 6);
    EXPECT_NE(close, std::string::npos);
    std::istringstream block(readme.substr(open + 6, close - open - 6));
    std::vector<std::string> out;
    std::string line;
    while (std::getline(block, line)) {
        const std::string command = line.substr(0, line.find('#'));
        if (command.find_first_not_of(' ') != std::string::npos) out.push_back(command);
    }
    return out;
}

TEST(Docs, EveryCommandOfTheHelpIsNamedInTheDocs) {
    const std::string text = docs();
    const std::set<std::string> commands = subcommands({});
    EXPECT_GE(commands.size(), 10u);  // scene, simulate, cast, structures, run, query, …
    for (const std::string& c : commands) EXPECT_NE(text.find("rcbench " + c), std::string::npos) << c;
    const std::set<std::string> scene = subcommands({"scene"});
    EXPECT_GE(scene.size(), 4u);  // gen, import, info, features
    for (const std::string& c : scene) EXPECT_NE(text.find("rcbench scene " + c), std::string::npos) << "scene " << c;
}

TEST(Docs, EveryStructureIsNamedInTheDocs) {
    const std::string text = docs();
    const test::Outcome r = rcbench({"structures"});
    ASSERT_EQ(r.code, 0) << r.err;
    std::istringstream lines(r.out);
    std::string line;
    std::size_t structures = 0;
    const std::regex heading(R"(^([a-z][a-z0-9_]*): )");
    std::smatch m;
    while (std::getline(lines, line)) {
        if (!std::regex_search(line, m, heading)) continue;
        ++structures;
        const std::string name = m[1];
        EXPECT_NE(text.find("`" + name + "`"), std::string::npos) << name;
    }
    EXPECT_GE(structures, 10u);  // bf, ug, hg, dbvh, lbvh, wbvh, embree, bullet_dbvt, ode_quadtree, ode_hash
}

TEST(Docs, EveryCommandTheDocsNameExists) {
    const std::set<std::string> commands = subcommands({});
    const std::set<std::string> scene = subcommands({"scene"});
    // In prose a command is written `rcbench NAME …`; in a code block, build/rcbench NAME or, in a
    // comment, rcbench NAME.
    const std::regex named(R"((?:`|build/|: )rcbench ([a-z][a-z_-]*)(?: ([a-z][a-z_-]*))?)");
    std::size_t checked = 0;
    for (const char* file : {"README.md", "docs/architecture.md"}) {
        const std::string text = read_source(file);
        for (std::sregex_iterator it(text.begin(), text.end(), named), end; it != end; ++it) {
            ++checked;
            const std::string command = (*it)[1];
            EXPECT_TRUE(commands.count(command)) << file << ": rcbench " << command;
            if (command == "scene") {
                EXPECT_TRUE(scene.count((*it)[2])) << file << ": rcbench scene " << (*it)[2];
            }
        }
    }
    EXPECT_GE(checked, 30u);
}

TEST(Docs, UsingItCommandsTakeTheirOptionsAndFilesExist) {
    const std::vector<std::string> lines = using_it_lines();
    ASSERT_GE(lines.size(), 30u);
    const fs::path source = RCBENCH_SOURCE_DIR;
    for (const std::string& line : lines) {
        std::istringstream in(line);
        std::vector<std::string> words;
        for (std::string w; in >> w;) words.push_back(w);
        std::string help;
        if (words[0] == "build/rcbench") {
            std::vector<std::string> command;  // empty for `build/rcbench --help`
            if (words[1][0] != '-') command.push_back(words[1]);
            if (words[1] == "scene") command.push_back(words[2]);
            command.push_back("--help");
            const test::Outcome r = rcbench(command);
            EXPECT_EQ(r.code, 0) << line << "\n" << r.err;
            help = r.out;
        } else if (words[0].rfind("build/bench/", 0) == 0) {
            const std::string name = words[0].substr(std::string("build/bench/").size());
            EXPECT_TRUE(fs::is_regular_file(source / "bench" / (name + ".cpp"))) << line;
        } else {
            EXPECT_TRUE(fs::is_regular_file(source / words[0])) << line;  // scripts/…, experiments/…
        }
        for (const std::string& w : words) {
            if (w.rfind("--", 0) == 0 && !help.empty()) {
                EXPECT_TRUE(has_option(help, w.substr(0, w.find('=')))) << line << ": " << w;
            }
            if (w.rfind("experiments/", 0) == 0 || w.rfind("scripts/", 0) == 0) {
                EXPECT_TRUE(fs::is_regular_file(source / w)) << line << ": " << w;
            }
        }
    }
}

/// Maps and models are fetched on demand, never committed: an experiment naming one that is not
/// there says which command fetches it; any other missing file does not.
TEST(Docs, MissingFetchedDataNamesTheScript) {
    const fs::path dir = fs::temp_directory_path() / ("rcb_docs_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    const auto run_with = [&](const std::string& import) {
        std::ofstream(dir / "exp.json") << R"({"name": "x", "structures": [{"name": "bf"}], "scenes": [{"import": ")"
                                        << import << R"("}]})";
        test::RunOptions o;
        o.cwd = dir.string();
        o.timeout_seconds = 120;
        return test::run_process({RCBENCH_BINARY, "run", "exp.json", "--db", "x.db"}, o);
    };
    const test::Outcome fetched = run_with("data/maps/absent.pk3");
    EXPECT_EQ(fetched.code, 2);
    EXPECT_NE(fetched.err.find("scenes[0].import: file not found: data/maps/absent.pk3"), std::string::npos)
        << fetched.err;
    EXPECT_NE(fetched.err.find("scripts/fetch_maps.sh"), std::string::npos) << fetched.err;
    EXPECT_EQ(std::count(fetched.err.begin(), fetched.err.end(), '\n'), 1) << fetched.err;
    // A set fetched by an argument of the script names the argument.
    const test::Outcome nexuiz = run_with("data/maps-nexuiz/absent.pk3");
    EXPECT_EQ(nexuiz.code, 2);
    EXPECT_NE(nexuiz.err.find("(scripts/fetch_maps.sh nexuiz fetches it)"), std::string::npos) << nexuiz.err;
    const test::Outcome tracks = run_with("data/tracks-torcs/absent.acc");
    EXPECT_EQ(tracks.code, 2);
    EXPECT_NE(tracks.err.find("(scripts/fetch_maps.sh torcs fetches it)"), std::string::npos) << tracks.err;
    const test::Outcome own = run_with("levels/absent.csv");
    EXPECT_EQ(own.code, 2);
    EXPECT_NE(own.err.find("file not found: levels/absent.csv"), std::string::npos) << own.err;
    EXPECT_EQ(own.err.find("fetch_maps"), std::string::npos) << own.err;
    fs::remove_all(dir);
}

/// The first group of every line of `text` that one of `patterns` matches (the first that does).
std::set<std::string> first_groups(const std::string& text, const std::vector<std::regex>& patterns) {
    std::set<std::string> out;
    std::istringstream in(text);
    for (std::string line; std::getline(in, line);) {
        std::smatch m;
        for (const std::regex& p : patterns)
            if (std::regex_search(line, m, p)) {
                out.insert(m[1]);
                break;
            }
    }
    return out;
}

/// The headings (without the #s) and bold paragraph leads (**Lead.**, without the stars and the
/// final stop) of a markdown file: what a citation `docs/NAME.md, "Section"` may name.
std::set<std::string> sections_of(const std::string& text) {
    return first_groups(text, {std::regex(R"(^#+\s+(.*\S)\s*$)"), std::regex(R"(^\*\*([^*]+?)\.?\*\*)")});
}

// A comment or doc that cites `docs/NAME.md, "Section"` (or `[NAME.md](NAME.md), "Section"`)
// sends the reader to a section that exists, unless it names the commit it cites ("as of commit
// ..."), where git keeps the text. Sections move and leave; a citation that outlives them misleads.
TEST(Docs, EverySectionTheSourcesCiteExists) {
    const std::regex cite(R"re((?:docs/|\[)([a-z0-9_-]+)\.md(?:\]\([a-z0-9_-]+\.md\))?, "([^"]+)")re");
    const std::regex line_break(R"(\s*\n\s*(///|//|#)?\s*)");
    std::vector<std::string> missing;
    std::map<std::string, std::set<std::string>> sections;
    const fs::path root(RCBENCH_SOURCE_DIR);
    for (const char* dir : {"analysis", "cli", "core", "accel", "sim", "runner", "tuner", "bench", "docs",
                            "experiments", "scripts", "tests"}) {
        for (const auto& e : fs::recursive_directory_iterator(root / dir)) {
            if (!e.is_regular_file()) continue;
            const std::string ext = e.path().extension().string();
            if (ext != ".h" && ext != ".cpp" && ext != ".md" && ext != ".sh" && ext != ".json") continue;
            if (e.path().filename() == "docs_test.cpp") continue;
            std::ifstream in(e.path());
            const std::string text(std::istreambuf_iterator<char>(in), {});
            for (std::sregex_iterator it(text.begin(), text.end(), cite), end; it != end; ++it) {
                const std::string doc = (*it)[1];
                // A citation wrapped over comment lines: one space for the break and the markers.
                const std::string section = std::regex_replace(std::string((*it)[2]), line_break, " ");
                if (!fs::exists(root / "docs" / (doc + ".md"))) continue;  // another file of that name
                if (!sections.count(doc)) sections[doc] = sections_of(read_source("docs/" + doc + ".md"));
                // The citation names a heading or lead, or the start of one ("Query kinds" for
                // "Query kinds: all, closest, any").
                const auto& known = sections[doc];
                const bool found = std::any_of(known.begin(), known.end(), [&](const std::string& h) {
                    return h.rfind(section, 0) == 0 &&
                           (h.size() == section.size() || !std::isalnum(static_cast<unsigned char>(h[section.size()])));
                });
                if (!found)
                    missing.push_back(fs::relative(e.path(), root).string() + ": docs/" + doc + ".md, \"" + section +
                                      "\"");
            }
        }
    }
    EXPECT_TRUE(missing.empty()) << [&] {
        std::string s;
        for (const std::string& m : missing) s += m + "\n";
        return s;
    }();
}

// docs/architecture.md's layout table names every folder a newcomer meets: each top-level folder
// (but the hidden ones, build trees, cmake/ and fetched data/) and every folder under the stages
// core/, accel/ and sim/, so a folder that appears is described where the layout is read.
TEST(Docs, TheLayoutTableNamesEveryFolder) {
    const std::set<std::string> named =
        first_groups(read_source("docs/architecture.md"), {std::regex(R"(^\| `([a-z_/]+/)` \|)")});
    const fs::path root(RCBENCH_SOURCE_DIR);
    std::vector<std::string> missing;
    const auto check = [&](const fs::path& dir) {
        const std::string rel = fs::relative(dir, root).generic_string() + "/";
        if (!named.count(rel)) missing.push_back(rel);
    };
    // core/ is described folder by folder below; data/ holds fetched maps (git-ignored).
    const std::set<std::string> skipped{"cmake", "core", "data"};
    for (const auto& e : fs::directory_iterator(root)) {
        const std::string name = e.path().filename().string();
        if (!e.is_directory() || name.front() == '.' || name.rfind("build", 0) == 0 || skipped.count(name)) continue;
        check(e.path());
    }
    for (const char* stage : {"core", "accel", "sim"})
        for (const auto& e : fs::recursive_directory_iterator(root / stage)) {
            if (!e.is_directory()) continue;
            const std::string name = e.path().filename().string();
            if (name == "CMakeFiles") continue;
            check(e.path());
        }
    EXPECT_TRUE(missing.empty()) << [&] {
        std::string s = "folders docs/architecture.md's layout table does not name:";
        for (const std::string& m : missing) s += " " + m;
        return s;
    }();
}

}  // namespace
