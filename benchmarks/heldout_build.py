"""Build the held-out vector corpus (issue 29) from local snapshots of six public repositories
and split it in two by a hash of each file's name — before any file is loaded.

    .venv/bin/python benchmarks/heldout_build.py MIRROR_DIR

MIRROR_DIR holds one git directory per repository, ``owner+name/repo`` (a bare or normal
clone at any commit; the commit used is the one recorded in the manifest). Files are picked
by a fixed rule per source (every n-th name in sorted order), written under
``tests/data/vector_heldout/<source>/`` where their licence lets us commit them and under
``benchmarks/.heldout_cache/<source>/`` otherwise, and listed in
``benchmarks/heldout_manifest.json`` with repository, commit, path, licence and half
("tune" or "held-out": the first byte of sha1(source/name) even or odd)."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
COMMITTED = ROOT / "tests" / "data" / "vector_heldout"
CACHE = ROOT / "benchmarks" / ".heldout_cache"
W3C = "SVGViewTests/w3c/1.1F2/svg/"
# source: (repository, commit, licence, committed, rule(all paths) -> chosen paths)
SOURCES = {
    "w3c-svg11": ("exyte/SVGView", "fd9f0303bc2da37e5d1ea98f42835c8273361c7b",
                  "W3C Test Suite Licence / BSD-3-Clause (the test files' own)", True,
                  lambda ps: [p for s in ("painting", "masking", "struct", "text", "pservers")
                              for p in sorted(q for q in ps if q.startswith(f"{W3C}{s}-")
                                              and q.endswith(".svg"))[::6]]),
    "qcad": ("qcad/qcad", "32b31879ee4faf66aa88c1dcf9f71a7089d4e60d", "GPL-3.0", False,
             lambda ps: sorted(p for p in ps if p.startswith("examples/") and p.endswith(".dxf"))
             + sorted(p for p in ps if p.startswith("libraries/default/")
                      and p.endswith(".dxf"))[::8]),
    "librecad": ("LibreCAD/LibreCAD", "adb94b0959e934694574a7603f01edba745f0da9", "GPL-2.0",
                 False, lambda ps: sorted(p for p in ps if "/support/library/" in p
                                          and p.lower().endswith(".dxf"))[::120]),
    "kicad-esp32clock": ("vanceb/ESP32_Clock", "6994fd51170c413c638ed529ab0be1b962201bc8",
                         "none stated", False,
                         lambda ps: sorted(p for p in ps if p.startswith("kicad/")
                                           and p.endswith(".svg"))),
    "noto-emoji": ("googlefonts/noto-emoji", "b3e3051a088047d19fd4d49b1c3ac42fb8c3aaf8",
                   "Apache-2.0 (svg/LICENSE)", True,
                   lambda ps: sorted(p for p in ps if p.startswith("svg/emoji_u1f")
                                     and p.endswith(".svg"))[::500]),
    "region-flags": ("googlefonts/noto-emoji", "b3e3051a088047d19fd4d49b1c3ac42fb8c3aaf8",
                     "public domain (third_party/region-flags/LICENSE)", True,
                     lambda ps: sorted(p for p in ps if p.startswith("third_party/region-flags/"
                                                                     "svg/") and p.endswith(".svg"))[::90]),
}
LICENCE_FILES = {"noto-emoji": "svg/LICENSE", "region-flags": "third_party/region-flags/LICENSE"}


def half(source: str, name: str) -> str:
    """"tune" or "held-out", from the first byte of sha1("source/name")."""
    return "tune" if hashlib.sha1(f"{source}/{name}".encode()).digest()[0] % 2 == 0 \
        else "held-out"


def git(repo: Path, *args: str) -> bytes:
    return subprocess.run(["git", "-C", str(repo), *args], check=True,
                          capture_output=True).stdout


def main(mirrors: Path) -> None:
    rows = []
    for source, (repo, commit, licence, committed, rule) in SOURCES.items():
        gitdir = mirrors / repo.replace("/", "+") / "repo"
        paths = git(gitdir, "ls-tree", "-r", "--name-only", commit).decode().splitlines()
        dest = (COMMITTED if committed else CACHE) / source
        dest.mkdir(parents=True, exist_ok=True)
        for p in rule(paths):
            name = Path(p).name
            (dest / name).write_bytes(git(gitdir, "show", f"{commit}:{p}"))
            rows.append({"source": source, "file": name, "repo": repo, "commit": commit,
                         "path": p, "licence": licence, "committed": committed,
                         "half": half(source, name)})
        if committed and source in LICENCE_FILES:
            (dest / "LICENSE").write_bytes(git(gitdir, "show",
                                               f"{commit}:{LICENCE_FILES[source]}"))
    (ROOT / "benchmarks" / "heldout_manifest.json").write_text(json.dumps(rows, indent=1) + "\n")
    n = {h: sum(r["half"] == h for r in rows) for h in ("tune", "held-out")}
    print(f"{len(rows)} files from {len(SOURCES)} sources: {n}")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
