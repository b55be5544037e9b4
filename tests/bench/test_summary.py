"""The leaderboard's numbers live in a pure module: its docstring examples compute what they claim, and it
reads and writes nothing (the report module lays out what it computes)."""
import ast
import doctest
import inspect

import bench.summary


def test_summary_docstring_examples():
    result = doctest.testmod(bench.summary, optionflags=doctest.ELLIPSIS)
    assert result.attempted >= 6 and result.failed == 0


def test_summary_does_no_io():
    tree = ast.parse(inspect.getsource(bench.summary))
    imported = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    imported |= {n.module.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
    assert imported <= {"__future__", "re", "warnings", "numpy", "pandas", "bench"}
    calls = {n.func.attr if isinstance(n.func, ast.Attribute) else getattr(n.func, "id", "")
             for n in ast.walk(tree) if isinstance(n, ast.Call)}
    assert not calls & {"open", "read_parquet", "to_parquet", "write_text", "read_text", "write_bytes", "savefig"}
