// rcbench archive add | unpack | verify: the results archive behind docs/ (results/README.md).
#include <algorithm>
#include <iostream>
#include <memory>

#include "cli/cli_checks.h"
#include "cli/commands.h"
#include "cli/table.h"
#include "core/base/error.h"
#include "runner/archive.h"

namespace rcb {

namespace {

/// The size the archive is kept under, in git beside the code (results/README.md).
constexpr std::int64_t kArchiveBudgetBytes = 30'000'000;

std::string megabytes(std::int64_t bytes) { return fixed(double(bytes) / 1e6, 2) + " MB"; }

/// The runs' experiments and commits, each once, comma-separated.
std::string distinct_of(const nlohmann::json& runs, const char* key) {
    std::vector<std::string> seen;
    for (const auto& r : runs)
        if (std::find(seen.begin(), seen.end(), r[key].get<std::string>()) == seen.end())
            seen.push_back(r[key].get<std::string>());
    std::string out;
    for (const std::string& s : seen) out += (out.empty() ? "" : ", ") + s;
    return out;
}

void print_added(const nlohmann::json& m, const std::filesystem::path& dir) {
    std::cout << "archived " << m["name"].get<std::string>() << ": " << m["runs"].size() << " runs of "
              << distinct_of(m["runs"], "experiment") << " (commit " << distinct_of(m["runs"], "git_commit") << "), "
              << m["rows"].value("cell", 0) << " cells, " << m["rows"].value("frame", 0) << " frames; "
              << megabytes(m["db_bytes"].get<std::int64_t>()) << " as a database, "
              << megabytes(m["bytes"].get<std::int64_t>()) << " compressed\n"
              << "  " << (dir / m["file"].get<std::string>()).string() << " and its manifest "
              << (dir / (m["name"].get<std::string>() + ".json")).string() << '\n';
    for (const auto& r : m["runs"])
        if (r["finished_at"].is_null())
            std::cerr << "note: run " << r["id"].get<std::int64_t>() << " (" << r["experiment"].get<std::string>()
                      << ") was unfinished when archived: its manifest says \"finished_at\": null\n";
    if (m["dirty"].get<bool>())
        std::cerr << "WARNING: " << m["name"].get<std::string>()
                  << " holds runs built from a DIRTY tree (marked \"dirty\": true in its manifest): their code "
                     "cannot be checked out again\n";
}

void print_verified(const std::vector<nlohmann::json>& manifests, const std::filesystem::path& dir) {
    TextTable t({"export", "runs", "experiments", "commits", "archived", "compressed", "dirty"});
    std::int64_t total = 0;
    for (const auto& m : manifests) {
        total += m["bytes"].get<std::int64_t>();
        t.add({m["name"].get<std::string>(), std::to_string(m["runs"].size()), distinct_of(m["runs"], "experiment"),
               distinct_of(m["runs"], "git_commit"), m["archived_at"].get<std::string>(),
               megabytes(m["bytes"].get<std::int64_t>()), m["dirty"].get<bool>() ? "DIRTY" : "no"});
    }
    t.print(std::cout);
    std::cout << manifests.size() << " exports in " << dir.string() << ", " << megabytes(total)
              << " in all; each matches the SHA-256 its manifest recorded\n";
    if (total > kArchiveBudgetBytes)
        std::cerr << "WARNING: the archive holds more than its budget of " << megabytes(kArchiveBudgetBytes)
                  << " (results/README.md): keep the exports the docs' figures read\n";
}

}  // namespace

void add_archive_command(CLI::App& app) {
    CLI::App* archive = app.add_subcommand(
        "archive",
        "The results archive behind the docs' figures: add, unpack, verify (results/README.md)\n"
        "The results archive behind the docs' figures: add a database as a compressed export with its manifest, "
        "unpack one, verify all (results/README.md)");
    archive->require_subcommand(1);

    struct AddOptions {
        ArchiveRequest request;
        std::string dir = "results/archive";
    };
    auto o = std::make_shared<AddOptions>();
    ArchiveRequest* a = &o->request;
    CLI::App* add = archive->add_subcommand(
        "add",
        "Export a results database (every table and frame, without frame.stats) to ARCHIVE/NAME.db.xz with a "
        "manifest ARCHIVE/NAME.json (commit, command, machine, load, dates, row counts, SHA-256); never replaces an "
        "export, refuses runs built from a dirty tree unless --allow-dirty");
    add->add_option("db", a->source, "Results database to archive")->required()->check(input_file());
    add->add_option("--name", a->name, "The export's name: letters, digits, '.', '_', '-'")->required();
    add->add_option("--command", a->command, "The command that made its runs, as typed (recorded in the manifest)")
        ->required();
    add->add_option("--archive", o->dir, "Archive folder")->capture_default_str();
    add->add_flag("--allow-dirty", a->allow_dirty,
                  "Archive runs built from a dirty tree, marked dirty in the manifest");
    add->callback([o] {
        o->request.archive_dir = o->dir;
        print_added(add_to_archive(o->request), o->request.archive_dir);
    });

    auto unpack = std::make_shared<std::pair<std::string, std::string>>();
    CLI::App* un = archive->add_subcommand(
        "unpack", "Unpack an export into a new results database, after checking its SHA-256 against its manifest");
    un->add_option("export", unpack->first, "An export, ARCHIVE/NAME.db.xz")->required()->check(input_file());
    un->add_option("-o,--output", unpack->second, "Database file to write (must not exist)")->required();
    un->callback([unpack] {
        unpack_export(unpack->first, unpack->second);
        std::cout << "unpacked " << unpack->first << " into " << unpack->second << '\n';
    });

    auto verify_dir = std::make_shared<std::string>("results/archive");
    CLI::App* verify = archive->add_subcommand(
        "verify", "Check that every export has its manifest and the SHA-256 it recorded, and list them");
    verify->add_option("archive", *verify_dir, "Archive folder")->capture_default_str();
    verify->callback([verify_dir] { print_verified(verify_archive(*verify_dir), *verify_dir); });
}

}  // namespace rcb
