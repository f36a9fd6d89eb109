#!/usr/bin/env python3
"""The manual's pages as issue 52 asks: RESULTS.md names no folder of one
machine in its commands, dataset.md stays a reference page under 600 lines,
and every relative link between pages finds its page and heading.

  docs_check.py DOCS_DIR
"""
import os
import re
import sys

MACHINE_FOLDERS = re.compile(r"(?<![\w.~$])/(?:work|tmp|home|root|mnt)/")
LINK = re.compile(r"\]\(([^)\s]+)\)")


def slug(heading):
    """A heading's anchor as GitHub makes it."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def anchors(path):
    found, in_code = set(), False
    for line in open(path, encoding="utf-8"):
        if line.startswith("```"):
            in_code = not in_code
        elif not in_code and line.startswith("#"):
            found.add(slug(line.lstrip("#")))
    return found


def main():
    docs = sys.argv[1]
    problems = []
    results = os.path.join(docs, "RESULTS.md")
    for number, line in enumerate(open(results, encoding="utf-8"), 1):
        if MACHINE_FOLDERS.search(line):
            problems.append(f"{results}:{number}: names a folder of one machine: {line.strip()}")
    dataset = os.path.join(docs, "dataset.md")
    lines = sum(1 for _ in open(dataset, encoding="utf-8"))
    if lines >= 600:
        problems.append(f"{dataset}: {lines} lines; a reference page stays under 600")
    pages = sorted(f for f in os.listdir(docs) if f.endswith(".md"))
    for page in pages:
        path = os.path.join(docs, page)
        for number, line in enumerate(open(path, encoding="utf-8"), 1):
            for target in LINK.findall(line):
                if re.match(r"[a-z]+:", target) or not (".md" in target or target.startswith("#")):
                    continue
                file, _, anchor = target.partition("#")
                linked = os.path.normpath(os.path.join(docs, file)) if file else path
                if not os.path.exists(linked):
                    problems.append(f"{path}:{number}: no page {file}")
                elif anchor and linked.endswith(".md") and anchor not in anchors(linked):
                    problems.append(f"{path}:{number}: no heading #{anchor} in {file or page}")
    for p in problems:
        print(p)
    print(f"docs_check: {len(pages)} pages, {len(problems)} problems")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
