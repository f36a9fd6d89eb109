"""Shared by the tools' end-to-end checks: counted checks, subprocess runs, and
the bad-input contract (one line on stderr naming the file, a non-zero exit
code, no output file left behind)."""
import os
import subprocess

checks = failures = 0


def check(label, ok, detail=""):
    global checks, failures
    checks += 1
    failures += not ok
    print(f"{'ok  ' if ok else 'FAIL'} {label}{'' if ok else ': ' + str(detail)[:2000]}", flush=True)


def run(cmd, timeout=600, **kw):
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, **kw)


def expect_error(label, cmd, must_name, no_file=None, code=1):
    out = run(cmd)
    lines = out.stderr.strip().splitlines()
    check(f"{label}: exit {code}", out.returncode == code, f"exit {out.returncode}, stderr {out.stderr!r}")
    check(f"{label}: one line naming {os.path.basename(must_name)}",
          len(lines) == 1 and must_name in lines[0], repr(out.stderr))
    if no_file:
        check(f"{label}: no output file", not os.path.exists(no_file), no_file)


def summary():
    """Prints the closing count line and returns the exit code."""
    print(f"{checks - failures} passed, {failures} failed")
    return 1 if failures else 0
