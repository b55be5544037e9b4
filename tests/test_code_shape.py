"""The shape of the product code (issue 9): no function longer than 80 lines, no block of more than
10 lines written twice.

Product code is every ``*.py`` under the product packages (``PRODUCT``), tests aside. Both checks
are plain and stated here, so a failure names ``file:line`` places a person can open:

* a function's length is ``end_lineno - lineno + 1`` of its ``def`` (``ast``; decorators not
  counted, nested functions counted inside their parent as well as on their own);
* a duplicate is a run of at least ``MIN_SHARED`` consecutive *normalised* lines (comments and blank
  lines removed, runs of whitespace folded to one space, leading indentation dropped) standing in two
  places, in two files or twice in one file without overlap.

The detectors are tested on small synthetic trees first, so the whole-tree checks can fail.
"""
from __future__ import annotations

import ast
import io
import tokenize
from collections import defaultdict
from dataclasses import dataclass
from itertools import combinations
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PRODUCT = ("capture", "align", "methods", "bench", "depthbench", "perf", "data_manifests")
MAX_FUNCTION_LINES = 80
MIN_SHARED = 11          # "no block of more than 10 lines stands twice"


# ----------------------------------------------------------------------------------- detectors
def product_sources(root: Path, packages=PRODUCT) -> dict[str, str]:
    """``{path relative to root: text}`` of every ``*.py`` below the given top-level folders."""
    out = {}
    for pkg in packages:
        for path in sorted((root / pkg).rglob("*.py")):
            out[path.relative_to(root).as_posix()] = path.read_text(encoding="utf-8")
    return out


def long_functions(sources: dict[str, str], *, limit: int = MAX_FUNCTION_LINES) -> list[str]:
    """``"file:line name (N lines)"`` for every function or method longer than ``limit`` lines."""
    found = []
    for name, text in sources.items():
        for node in ast.walk(ast.parse(text, filename=name)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > limit:
                    found.append(f"{name}:{node.lineno} {node.name} ({n} lines)")
    return sorted(found)


def normalised_lines(text: str) -> list[tuple[int, str]]:
    """``(line number, text)`` of the lines that hold code: comments cut (found by the tokenizer, so a
    ``#`` inside a string stays), blank lines dropped, whitespace folded, indentation removed."""
    lines = text.splitlines()
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type == tokenize.COMMENT:
            row, col = tok.start
            lines[row - 1] = lines[row - 1][:col]
    out = []
    for k, line in enumerate(lines, start=1):
        folded = " ".join(line.split())
        if folded:
            out.append((k, folded))
    return out


@dataclass(frozen=True)
class Duplicate:
    """Lines ``a_first..a_last`` of ``a`` stand again, normalised, at ``b_first..b_last`` of ``b``."""

    a: str
    a_first: int
    a_last: int
    b: str
    b_first: int
    b_last: int

    def __str__(self) -> str:
        return f"{self.a}:{self.a_first}-{self.a_last} ~ {self.b}:{self.b_first}-{self.b_last}"


def duplicate_blocks(sources: dict[str, str], *, min_lines: int = MIN_SHARED) -> list[Duplicate]:
    """Every maximal run of at least ``min_lines`` normalised lines that stands in two places."""
    norm = {name: normalised_lines(text) for name, text in sources.items()}
    windows: dict[tuple[str, ...], list[tuple[str, int]]] = defaultdict(list)
    for name, lines in norm.items():
        texts = [t for _, t in lines]
        for k in range(len(texts) - min_lines + 1):
            windows[tuple(texts[k:k + min_lines])].append((name, k))
    pairs = set()
    for places in windows.values():
        for (fa, ka), (fb, kb) in combinations(places, 2):
            if fa != fb or abs(ka - kb) >= min_lines:        # one repeated pattern overlapping itself is no copy
                pairs.add((fa, ka, fb, kb))
    found = []
    for fa, ka, fb, kb in sorted(pairs):
        if (fa, ka - 1, fb, kb - 1) in pairs:                 # inside a longer run, reported from its start
            continue
        n = 0
        while (fa, ka + n + 1, fb, kb + n + 1) in pairs:
            n += 1
        last = min_lines - 1 + n
        found.append(Duplicate(fa, norm[fa][ka][0], norm[fa][ka + last][0], fb, norm[fb][kb][0], norm[fb][kb + last][0]))
    return found


# ----------------------------------------------------------------------------------- the detectors work
def _body(k: int, *, tag: str = "x") -> str:
    return "".join(f"    total += {tag}[{i}] * {i}\n" for i in range(k))


def test_long_functions_counts_def_to_last_line_including_nested_ones(tmp_path):
    src = {
        "pkg/a.py": "def short():\n" + _body(79) + "\n\ndef long_one():\n" + _body(80),
        "pkg/b.py": "class C:\n    @staticmethod\n    def method(self):\n        def inner():\n" + "".join(
            f"            y = {i}\n" for i in range(85)) + "        return inner\n",
    }
    got = long_functions(src)
    assert got == ["pkg/a.py:83 long_one (81 lines)", "pkg/b.py:3 method (88 lines)", "pkg/b.py:4 inner (86 lines)"]
    (tmp_path / "pkg").mkdir()
    for name, text in src.items():
        (tmp_path / name).write_text(text)
    assert long_functions(product_sources(tmp_path, ("pkg",))) == got


def test_duplicates_ignore_comments_blank_lines_and_whitespace_and_name_both_places():
    block = [f"value_{i} = compute({i}, scale=2)" for i in range(12)]
    a = "import os\n\n" + "\n".join(block) + "\nprint('a')\n"
    b = ("def f():\n    pass\n" + "\n".join(
        f"{line}   # a comment\n\n" if i % 3 == 0 else line.replace(" = ", "   =   ") + "\n"
        for i, line in enumerate(block)) + "print('b')\n")
    found = duplicate_blocks({"a.py": a, "b.py": b})
    assert [str(d) for d in found] == ["a.py:3-14 ~ b.py:3-29"]
    # a hash inside a string is code, not a comment: changing it breaks the match
    c = a.replace("compute(5, scale=2)", "compute('#5', scale=2)")
    assert duplicate_blocks({"a.py": a, "c.py": c}, min_lines=11) == []


def test_ten_shared_lines_pass_eleven_fail_and_a_file_can_repeat_itself():
    ten = "\n".join(f"step_{i}(data)" for i in range(10)) + "\n"
    eleven = "\n".join(f"step_{i}(data)" for i in range(11)) + "\n"
    assert duplicate_blocks({"a.py": ten + "x = 1\n", "b.py": "y = 2\n" + ten}) == []
    assert [str(d) for d in duplicate_blocks({"a.py": eleven, "b.py": "y = 2\n" + eleven})] == ["a.py:1-11 ~ b.py:2-12"]
    twice = eleven + "middle()\n" + eleven
    assert [str(d) for d in duplicate_blocks({"t.py": twice})] == ["t.py:1-11 ~ t.py:13-23"]
    same_line = "pass\n" * 30                      # one line repeated: overlapping windows are not copies...
    assert all(abs(d.a_first - d.b_first) >= MIN_SHARED for d in duplicate_blocks({"p.py": same_line}))


# ----------------------------------------------------------------------------------- the product tree
@pytest.fixture(scope="module")
def product_tree() -> dict[str, str]:
    return product_sources(REPO)


def test_no_product_function_is_longer_than_80_lines(product_tree):
    found = long_functions(product_tree)
    assert not found, "functions longer than 80 lines:\n" + "\n".join(found)


def test_no_block_of_more_than_10_lines_stands_twice_in_product_code(product_tree):
    found = duplicate_blocks(product_tree)
    assert not found, "blocks of more than 10 lines written twice:\n" + "\n".join(map(str, found))
