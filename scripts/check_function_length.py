#!/usr/bin/python3
"""Lists the functions of rcbench's libraries and tools longer than a limit (default 120 lines, body
included) and fails when there is one: orchestration is cut into named steps. Tests are exempt, and
so is data that is a table by nature (the schema migrations). Parses with libclang (Debian's
python3-clang-14) using the flags of BUILD/compile_commands.json, one translation unit per process
on every core it may use (parsing is the whole cost, and CI waits for it).

  scripts/check_function_length.py BUILD [--limit N] [--all]
"""
import argparse
import json
import multiprocessing
import os
import shlex
import sys

import clang.cindex as ci

ci.Config.set_library_file("/usr/lib/llvm-14/lib/libclang.so.1")
FOLDERS = ("core/", "accel/", "sim/", "runner/", "analysis/", "tuner/", "cli/", "bench/")
EXEMPT = {("runner/store.cpp", "migrations")}  # the schema migrations: SQL text as data
KINDS = {ci.CursorKind.FUNCTION_DECL, ci.CursorKind.CXX_METHOD, ci.CursorKind.CONSTRUCTOR,
         ci.CursorKind.DESTRUCTOR, ci.CursorKind.FUNCTION_TEMPLATE, ci.CursorKind.LAMBDA_EXPR,
         ci.CursorKind.CONVERSION_FUNCTION}


def functions_of(root_and_command):
    """The definitions in one translation unit's project files: (file, line) -> (lines, name)."""
    root, c = root_and_command
    args = shlex.split(c["command"])[1:]
    args = [x for x in args if x not in ("-c",) and not x.endswith((".cpp", ".o")) and x != "-o"]
    tu = ci.Index.create().parse(c["file"], args=args + ["-Wno-everything"])
    seen = {}
    stack = [tu.cursor]
    while stack:
        cur = stack.pop()
        loc = cur.location.file
        if loc is not None:
            rel = os.path.relpath(loc.name, root)
            if not rel.startswith(FOLDERS):
                continue
        lambda_expr = cur.kind == ci.CursorKind.LAMBDA_EXPR
        if cur.kind in KINDS and (lambda_expr or cur.is_definition()) and (rel, cur.spelling) not in EXEMPT:
            lines = cur.extent.end.line - cur.extent.start.line + 1
            seen[(rel, cur.extent.start.line)] = (lines, cur.spelling or "a lambda")
        stack.extend(cur.get_children())
    return seen


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("build")
    ap.add_argument("--limit", type=int, default=120)
    ap.add_argument("--all", action="store_true", help="print every function over the limit's half")
    a = ap.parse_args()
    root = os.path.abspath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
    with open(os.path.join(a.build, "compile_commands.json")) as f:
        commands = json.load(f)
    root_args = [(root, c) for c in commands if os.path.relpath(c["file"], root).startswith(FOLDERS)]
    seen = {}
    with multiprocessing.Pool(len(os.sched_getaffinity(0))) as pool:
        for found in pool.imap_unordered(functions_of, root_args):
            seen.update(found)
    over = sorted(((n, f, l, name) for (f, l), (n, name) in seen.items() if n > a.limit), reverse=True)
    if a.all:
        for n, f, l, name in sorted(((n, f, l, name) for (f, l), (n, name) in seen.items()
                                     if n > a.limit // 2), reverse=True):
            print(f"{f}:{l}: {name} {n} lines")
    for n, f, l, name in over:
        print(f"{f}:{l}: {name} is {n} lines, over {a.limit}: cut it into named steps", file=sys.stderr)
    print(f"function length: {len(seen)} functions, {len(over)} over {a.limit} lines")
    return 1 if over else 0


if __name__ == "__main__":
    sys.exit(main())
