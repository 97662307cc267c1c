#!/usr/bin/env python3
"""Fails (one line per place) where C++ code ends the process below main.

Every program's main returns its status; below it, code returns a result or throws
laserline::cli::Exit (tools/cli.hpp), which the main catches, so that the stack unwinds and each
owner closes what it holds. exit, std::exit, quick_exit and _Exit are therefore refused
everywhere. _exit is allowed only in the files listed in ALLOWED_UNDERSCORE_EXIT, each with its
reason. Comments and string literals are not code and are not searched.

  scripts/check-no-exit.py [ROOT]    (default: the checkout this script is in)
"""
import os
import re
import subprocess
import sys

ALLOWED_UNDERSCORE_EXIT = {
    # The signal thread ends a daemon that is still starting at once (the laser was never on);
    # exit() there would race the main thread's destructors.
    "daemon/laserlined.cpp",
    # A forked child whose exec failed must not run the parent's atexit handlers and destructors.
    "tests/run_command.hpp",
    "tests/test_aravis_camera.cpp",
    "tests/test_gpio_laser.cpp",
    "tests/test_service_notify.cpp",
    "tests/test_v4l2_camera.cpp",
}

EXTENSIONS = (".cpp", ".hpp", ".cc", ".h", ".c")
FORBIDDEN = re.compile(r"(?<![\w.>])(?:std\s*::\s*|::\s*)?(exit|quick_exit|_Exit|_exit)\s*\(")
# A comment, a raw string, a string or a character literal (not a digit separator: 5'000).
NOT_CODE = re.compile(
    r'//[^\n]*|/\*.*?\*/|R"([^(\s]*)\(.*?\)\1"|"(?:\\.|[^"\\\n])*"|(?<![0-9A-Fa-f_])\'(?:\\.|[^\'\\\n])*\'',
    re.DOTALL,
)


def code_only(text):
    """The text with comments and literals blanked, newlines kept (line numbers hold)."""
    return NOT_CODE.sub(lambda m: re.sub(r"[^\n]", " ", m.group(0)), text)


def sources(root):
    try:
        listed = subprocess.run(
            ["git", "-C", root, "ls-files", "-z"], check=True, capture_output=True, text=True
        ).stdout.split("\0")
    except (OSError, subprocess.CalledProcessError):
        listed = []
        for folder, subfolders, names in os.walk(root):
            # Not the build trees nor hidden folders (.git).
            subfolders[:] = [d for d in subfolders if d != "build" and not d.startswith(".")]
            listed += [os.path.relpath(os.path.join(folder, name), root) for name in names]
    return sorted(f for f in listed if f.endswith(EXTENSIONS))


def problems(root):
    found = []
    for path in sources(root):
        try:
            with open(os.path.join(root, path), encoding="utf-8", errors="replace") as f:
                code = code_only(f.read())
        except FileNotFoundError:  # deleted in the work tree, not yet in git
            continue
        for match in FORBIDDEN.finditer(code):
            name = match.group(1)
            if name == "_exit" and path in ALLOWED_UNDERSCORE_EXIT:
                continue
            line = code.count("\n", 0, match.start()) + 1
            found.append(
                f"{path}:{line}: {name}() ends the process below main: return a result or throw "
                "laserline::cli::Exit"
            )
    return found


def main():
    root = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..")
    root = os.path.abspath(root)
    found = problems(root)
    for line in found:
        print(line)
    if found:
        return 1
    print(f"no exit below main in {len(sources(root))} C++ files")
    return 0


if __name__ == "__main__":
    sys.exit(main())
