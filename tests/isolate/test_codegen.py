"""Generated IF-THEN-ELSE code (Python and C) agrees with the diagnostic tree for every fault."""

import itertools
import shutil
import subprocess

import numpy as np
import pytest

from fdikit.errors import DataError
from fdikit.isolate import DMatrix, ao_star, compile_python, to_c, to_listing, to_python

TABLE_IV_TESTS = ["G_P1", "G_O1", "G_O2", "G_O_T1", "G_O_T2", "S_Kf", "S_Iw"]
TABLE_IV_FAULTS = ["F0", "F1.1", "F1.2", "F2.1", "F2.2", "F3", "F4", "F5"]
TABLE_IV = [[0, 0, 0, 0, 0, 0, 0], [0, 1, 1, 0, 1, 0, 0], [1, 1, 1, 0, 1, 0, 0], [0, 1, 1, 0, 0, 0, 0],
            [1, 1, 1, 0, 0, 0, 0], [0, 1, 1, 1, 0, 1, 0], [0, 1, 1, 1, 0, 0, 1], [0, 1, 0, 0, 0, 0, 0]]


def trees():
    """Hand-made and random trees, perfect and unreliable, with and without ambiguity groups."""
    out = [ao_star(DMatrix(TABLE_IV_FAULTS, TABLE_IV_TESTS, TABLE_IV), [0.93] + [0.01] * 7)]
    # an ambiguity group (b, d identical) and odd names that need quoting/escaping
    dm = DMatrix(["ok", "b", 'c"q', "d", "e*/"], ["t 1", "t-2", "t3"],
                 [[0, 0, 0], [1, 0, 1], [1, 1, 0], [1, 0, 1], [0, 1, 1]])
    out.append(ao_star(dm))
    for seed in range(4):
        rng = np.random.default_rng(seed)
        nf, nt = int(rng.integers(5, 11)), int(rng.integers(3, 8))
        dm = DMatrix([f"F{i}" for i in range(nf)], [f"T{j}" for j in range(nt)], rng.random((nf, nt)) < 0.5)
        out.append(ao_star(dm, rng.dirichlet(np.ones(nf)), rng.uniform(0.5, 2, nt)))
    rng = np.random.default_rng(9)
    dm = DMatrix(list("abcde"), ["u", "v", "w", "x"], rng.random((5, 4)) < 0.5,
                 pd=rng.uniform(0.7, 1, (5, 4)), pf=rng.uniform(0, 0.2, (5, 4)))
    out.append(ao_star(dm, misdiagnosis_cost=20.0))
    # degenerate: one fault; two faults that no test can separate (the root is a leaf)
    out.append(ao_star(DMatrix(["only"], ["t"], [[1]])))
    out.append(ao_star(DMatrix(["x", "y"], ["t1", "t2"], [[1, 0], [1, 0]])))
    return out


TREES = trees()


def all_outcomes(tree):
    nt = len(tree.dmatrix.tests)
    return [np.array(o, bool) for o in itertools.product((0, 1), repeat=nt)]


@pytest.mark.parametrize("k", range(len(TREES)))
def test_python_agrees_with_tree(k):
    tree = TREES[k]
    dm = tree.dmatrix
    f = compile_python(tree, "diag")
    # every fault, with its outcomes simulated from its D-matrix row
    for name in dm.faults:
        row = dm.row(name)
        outcomes = dict(zip(dm.tests, row.tolist()))
        got = f(outcomes)
        assert got == tree.diagnose(row)
        if tree.tests_model == "perfect":
            assert name in got                      # the fault is in the group the code returns
        # the callable form reads only the requested tests: exactly the tree's path
        asked = []
        assert f(lambda t, o=outcomes, a=asked: a.append(t) or o[t]) == got
        path, n = [], tree.root
        while not n.is_leaf:
            path.append(n.test)
            n = n.failed if outcomes[n.test] else n.passed
        assert asked == path
    # every possible outcome vector (unreliable tests can produce any)
    for o in all_outcomes(tree):
        assert f(dict(zip(dm.tests, o.tolist()))) == tree.diagnose(o)


def test_python_source_layout():
    src = to_python(TREES[0])
    assert "# Faults: F0, F1.1, F1.2, F2.1, F2.2, F3, F4, F5" in src
    body = src[src.index("def diagnose(outcomes):"):].splitlines()
    assert body[3] == "    if not get('G_O1'):  # G_O1 == G"
    with pytest.raises(DataError, match="not a valid identifier"):
        to_python(TREES[0], "my func")


C_MAIN = r"""
#include <stdio.h>
int main(void)
{
    int o[%(nt)d];
    for (;;) {
        for (int j = 0; j < %(nt)d; ++j)
            if (scanf("%%d", &o[j]) != 1) return 0;
        int k = diag(o);
        printf("%%d %%s\n", k, diag_leaf_names[k]);
    }
}
"""


@pytest.mark.skipif(shutil.which("gcc") is None,
                    reason="gcc is not installed: the generated C cannot be compiled")
@pytest.mark.parametrize("k", range(len(TREES)))
def test_c_compiles_and_agrees(k, tmp_path):
    tree = TREES[k]
    dm = tree.dmatrix
    nt = len(dm.tests)
    src = to_c(tree, "diag") + C_MAIN % {"nt": nt}
    (tmp_path / "diag.c").write_text(src)
    exe = tmp_path / "diag"
    res = subprocess.run(["gcc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-O1", "-o", str(exe),
                          str(tmp_path / "diag.c")], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    # every fault row first, then every outcome vector
    vectors = [dm.row(f) for f in dm.faults] + all_outcomes(tree)
    stdin = "\n".join(" ".join(str(int(v)) for v in o) for o in vectors) + "\n"
    run = subprocess.run([str(exe)], input=stdin, capture_output=True, text=True, timeout=30)
    assert run.returncode == 0, run.stderr
    lines = run.stdout.splitlines()
    assert len(lines) == len(vectors)
    leaves = tree.leaves()
    for o, line in zip(vectors, lines):
        idx, name = line.split(" ", 1)
        leaf = tree.leaf_for(o)
        assert leaves[int(idx)] is leaf
        assert name == " | ".join(leaf.group)


def test_c_header_lists_faults_tests_and_leaves():
    src = to_c(TREES[1], "diag")
    head = src[: src.index("*/")]
    assert "Faults: ok, b, c\"q, d, e* /" in head      # "*/" inside a name cannot end the comment
    assert "  0: t 1" in head and "  1: t-2" in head
    assert "b | d" in head                               # the ambiguity group is one leaf
    assert '"c\\"q"' in src                              # escaped in the string table


def test_degenerate_trees():
    tree = TREES[-1]
    assert tree.root.is_leaf and tree.depth == 0 and tree.go_path == []
    assert compile_python(tree)({}) == ("x", "y")
    assert to_listing(tree) == 'DISPLAY("x or y");'
    assert tree.expected_cost == 0.0


def test_listing_like_the_paper():
    # Table IV with P(F0) = 0.93: the listing starts like the paper's (Section VII)
    listing = to_listing(TREES[0], {"F0": "SYSTEM OK", "F3": "K_f fault", "F4": "I_w fault"})
    lines = listing.splitlines()
    assert lines[0] == 'IF G_O1 == G DISPLAY("SYSTEM OK");'
    assert lines[1].startswith("ELSE REQUEST ")
    # one DISPLAY per leaf, and the K_f / I_w leaves are separated by a single SVM test
    assert listing.count("DISPLAY(") == 8
    svm = [ln.strip() for ln in lines if ln.strip().startswith("IF S_")]
    assert len(svm) == 1
    assert svm[0].endswith('DISPLAY("I_w fault");') or svm[0].endswith('DISPLAY("K_f fault");')
