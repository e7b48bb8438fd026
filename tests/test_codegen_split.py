"""Large CasADi functions compiled in pieces (``codegen.compiled_by_key``) and IPOPT's compiled derivatives."""

from __future__ import annotations

import os

import casadi as ca
import numpy as np
import pytest

from wheelloader.estimator import Pile, PlanningError
from wheelloader.planner import PlannerOptions, TrajectoryOptimizer, codegen, cycle_duration, default_start, nlp

needs_cc = pytest.mark.skipif(codegen.compiler() is None, reason="no C compiler")


def _functions():
    """Two SX functions with the operations CasADi's generated C uses (helpers, constants, outputs)."""
    x = ca.SX.sym("x", 3)
    y = ca.SX.sym("y", 2)
    e = ca.sin(x[0]) * x[1] ** 2 + ca.log1p(ca.exp(-ca.fabs(x[2]))) / (1 + y[0] ** 2) + ca.fmax(x[0], y[1])
    f = ca.Function("wl_split_f", [x, y], [e, ca.vertcat(ca.sign(x[1]) * e, ca.tanh(e) - y[1], 0.5 * e ** 3)])
    jac = ca.Function("wl_split_jac", [x, y], [ca.jacobian(e, ca.vertcat(x, y))])
    hess = ca.Function("wl_split_hess", [x, y], [ca.hessian(e, x)[0]])
    return {"f": f, "jac": jac, "hess": hess}


@needs_cc
def test_pieces_evaluate_bit_for_bit_like_the_virtual_machine(tmp_path, monkeypatch):
    monkeypatch.setenv("WHEELLOADER_NLP_CACHE", str(tmp_path))
    monkeypatch.setattr(codegen, "SPLIT_STATEMENTS", 3)  # many pieces: values cross pieces and units
    monkeypatch.setattr(codegen, "SPLIT_FUNCTIONS", 2)
    functions = _functions()
    names = {key: f.name() for key, f in functions.items()}
    made = []
    compiled = codegen.compiled_by_key("key-1", names, lambda: made.append(1) or functions, "wl_split")
    assert compiled is not None and made == [1]
    assert codegen.LOG[-1]["status"] == "compiled" and codegen.LOG[-1]["units"] > 3
    rng = np.random.default_rng(4)
    for _ in range(20):
        point = [rng.normal(size=3), rng.normal(size=2)]
        for key, function in functions.items():
            expected = function(*point)
            got = compiled[key](*point)
            for a, b in zip(expected if isinstance(expected, (list, tuple)) else [expected],
                            got if isinstance(got, (list, tuple)) else [got], strict=True):
                assert np.array(a).tobytes() == np.array(b).tobytes(), key
    # found again by its key alone: nothing is made or compiled
    again = codegen.compiled_by_key("key-1", names, lambda: pytest.fail("made again"), "wl_split")
    assert again is not None and codegen.LOG[-1]["status"] == "loaded"
    assert len(list((tmp_path / "compiled").glob("wl_split-*.so"))) == 1
    # another key is another library
    codegen.compiled_by_key("key-2", names, lambda: functions, "wl_split")
    assert codegen.LOG[-1]["status"] == "compiled"
    assert len(list((tmp_path / "compiled").glob("wl_split-*.so"))) == 2


def test_unknown_generated_layout_falls_back(tmp_path, monkeypatch, caplog):
    with pytest.raises(ValueError, match="configuration marker"):
        codegen._split("int main(void) { return 0; }", "x")
    monkeypatch.setenv("WHEELLOADER_NLP_CACHE", str(tmp_path))
    monkeypatch.setattr(codegen, "compiler", lambda: "/bin/true")  # never reached: the split refuses first
    monkeypatch.setattr(codegen, "_split", lambda source, stem: (_ for _ in ()).throw(ValueError("unknown layout")))
    functions = _functions()
    assert codegen.compiled_by_key("k", {key: f.name() for key, f in functions.items()}, lambda: functions,
                                   "wl_split_bad") is None
    assert codegen.LOG[-1]["status"] == "failed: unknown layout"
    assert "virtual machine is used" in caplog.text


def _plan(options):
    pile = Pile.trapezoid()
    start = default_start(pile)
    return TrajectoryOptimizer(options=options).solve("gravel", pile, start, cycle_duration(pile, start))


def _same(a, b):
    for name in ("t", "x", "z", "blade_angle", "fill", "tangential", "normal"):
        assert np.array(getattr(a, name)).tobytes() == np.array(getattr(b, name)).tobytes(), name
    assert a.energy == b.energy and a.objective == b.objective and a.iterations == b.iterations


def test_ipopt_without_a_compiler_plans_like_the_virtual_machine(tmp_path, monkeypatch, caplog):
    monkeypatch.setenv("WHEELLOADER_NLP_CACHE", str(tmp_path))
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    monkeypatch.setattr(nlp, "_CACHE", {})
    plain = _plan(PlannerOptions(intervals=10))
    fallback = _plan(PlannerOptions(intervals=10, compiled=True))
    assert codegen.LOG[-1]["status"] == "failed: no C compiler" and "no C compiler" in caplog.text
    _same(plain, fallback)


@pytest.mark.slow
@needs_cc
def test_compiled_ipopt_plans_bit_for_bit_like_the_virtual_machine(tmp_path, monkeypatch):
    """IPOPT on compiled derivatives (a 10-interval NLP, about a minute of CPU to compile): the same plan; a
    second process (here: an emptied memory cache) loads the library by the NLP's key without differentiating."""
    monkeypatch.setenv("WHEELLOADER_NLP_CACHE", str(tmp_path))
    monkeypatch.setattr(nlp, "_CACHE", {})
    plain = _plan(PlannerOptions(intervals=10))
    compiled = _plan(PlannerOptions(intervals=10, compiled=True))
    assert codegen.LOG[-1]["status"] == "compiled"
    _same(plain, compiled)
    monkeypatch.setattr(nlp, "_CACHE", {})
    loaded = _plan(PlannerOptions(intervals=10, compiled=True))
    assert codegen.LOG[-1]["status"] == "loaded"
    (entry,) = nlp._CACHE.values()
    assert not entry["derivatives"]  # nothing was differentiated in CasADi's virtual machine
    _same(plain, loaded)


def test_demo_flag_reaches_the_planner(tmp_path, monkeypatch):
    import wheelloader.adaptation as adaptation
    from wheelloader.cli import main

    seen = []

    class Stop(Exception):
        pass

    def planner(**kwargs):
        seen.append(kwargs)
        raise Stop

    monkeypatch.setattr(adaptation, "default_planner", planner)
    for flags, compiled in (([], False), (["--compiled"], True)):
        with pytest.raises(Stop):
            main(["demo", "-o", str(tmp_path / f"demo{len(seen)}"), *flags])
        assert seen[-1] == {"mpc": False, "compiled": compiled}


def test_common_subexpressions_go_and_the_values_stay_bit_for_bit():
    x = ca.SX.sym("x", 2)
    shared = ca.sin(x[0] * x[1])
    # the same operation on the same operands, built twice: two instructions until the elimination
    f = ca.Function("wl_repeats", [x], [ca.sin(x[0] * x[1]) * shared + ca.exp(ca.sin(x[0] * x[1]))], ["x"], ["y"])
    g = codegen._without_repeats(f)
    assert g.n_instructions() < f.n_instructions()
    assert (g.name(), g.name_in(), g.name_out()) == (f.name(), f.name_in(), f.name_out())
    rng = np.random.default_rng(5)
    for _ in range(50):
        point = rng.normal(size=2) * 3
        assert np.array(f(point)).tobytes() == np.array(g(point)).tobytes()


def test_without_a_library_the_compiled_if_present_rule_plans_in_the_virtual_machine(tmp_path, monkeypatch):
    monkeypatch.setenv("WHEELLOADER_NLP_CACHE", str(tmp_path))
    monkeypatch.setattr(nlp, "_CACHE", {})
    plain = _plan(PlannerOptions(intervals=6))
    monkeypatch.setattr(nlp, "_CACHE", {})
    logged = len(codegen.LOG)
    previous = nlp.compiled_if_present(True)
    try:
        ruled = _plan(PlannerOptions(intervals=6))
    finally:
        nlp.compiled_if_present(previous)
    assert len(codegen.LOG) == logged  # nothing compiled, nothing loaded
    assert not (tmp_path / "compiled").exists()
    (entry,) = nlp._CACHE.values()
    assert entry["derivatives"]  # differentiated in CasADi's virtual machine
    _same(plain, ruled)
    with pytest.raises(PlanningError):
        nlp.compiled_if_present("yes")


@pytest.mark.slow
@needs_cc
def test_compiled_if_present_loads_the_library_a_compiled_run_left(tmp_path, monkeypatch):
    """A ``compiled=True`` run compiles the derivatives of a 10-interval NLP; a later process (an emptied memory
    cache) with ``compiled=False`` under :func:`nlp.compiled_if_present` loads that library: the same plan."""
    monkeypatch.setenv("WHEELLOADER_NLP_CACHE", str(tmp_path))
    monkeypatch.setattr(nlp, "_CACHE", {})
    plain = _plan(PlannerOptions(intervals=10))
    _plan(PlannerOptions(intervals=10, compiled=True))
    assert codegen.LOG[-1]["status"] == "compiled"
    monkeypatch.setattr(nlp, "_CACHE", {})
    previous = nlp.compiled_if_present(True)
    try:
        found = _plan(PlannerOptions(intervals=10))
    finally:
        nlp.compiled_if_present(previous)
    assert codegen.LOG[-1]["status"] == "loaded"
    (entry,) = nlp._CACHE.values()
    assert not entry["derivatives"]  # nothing was differentiated in CasADi's virtual machine
    _same(plain, found)


@needs_cc
def test_the_compiled_folder_keeps_the_most_recently_used_libraries(tmp_path, monkeypatch):
    monkeypatch.setenv("WHEELLOADER_NLP_CACHE", str(tmp_path))
    monkeypatch.setattr(codegen, "MAX_LIBRARIES", 2)
    x = ca.SX.sym("x")
    libraries = []
    for k in range(3):
        f = ca.Function("wl_prune", [x], [ca.sin(x) + k])
        made = codegen.compiled_by_key(f"prune-{k}", {"f": "wl_prune"}, lambda f=f: {"f": f}, "wl_prune")
        assert made is not None and float(made["f"](0.5)) == float(f(0.5))
        libraries.append(codegen.LOG[-1]["library"])
        if k == 1:  # the first one used again (loaded) before the third is compiled: the second one goes
            os.utime(libraries[0], (1, 1))
            os.utime(libraries[1], (2, 2))
            assert codegen.present_by_key("prune-0", {"f": "wl_prune"}, "wl_prune") is not None
    kept = sorted(str(path) for path in (tmp_path / "compiled").glob("*.so"))
    assert kept == sorted([libraries[0], libraries[2]])
    assert codegen.present_by_key("prune-1", {"f": "wl_prune"}, "wl_prune") is None


def test_a_failed_unit_stops_the_compile_and_falls_back(tmp_path, monkeypatch, caplog):
    """The units compile side by side; the first one that fails ends the compile (the rest are not started) and
    the caller keeps CasADi's virtual machine."""
    monkeypatch.setenv("WHEELLOADER_NLP_CACHE", str(tmp_path))
    monkeypatch.setattr(codegen, "SPLIT_STATEMENTS", 3)
    monkeypatch.setattr(codegen, "SPLIT_FUNCTIONS", 1)
    monkeypatch.setattr(codegen, "COMPILE_JOBS", 1)
    functions = _functions()
    units = len(codegen._split(codegen._c_source("wl_split_fail", map(codegen._without_repeats, functions.values())),
                               "wl_split_fail"))
    assert units > 5
    # the first unit fails at once, the later ones would take 0.2 s each
    script = tmp_path / "cc"
    calls_file = tmp_path / "calls"
    script.write_text(f"#!/bin/sh\nif [ -e {calls_file} ]; then sleep 0.2; echo unit >> {calls_file}; exit 0; fi\n"
                      f"echo unit >> {calls_file}\necho 'no such luck' >&2\nexit 1\n")
    script.chmod(0o755)
    monkeypatch.setenv("CC", str(script))
    assert codegen.compiled_by_key("k-fail", {key: f.name() for key, f in functions.items()}, lambda: functions,
                                   "wl_split_fail") is None
    calls = calls_file.read_text().split()
    assert codegen.LOG[-1]["status"] == "failed: no such luck" and "virtual machine is used" in caplog.text
    assert len(calls) < units  # the units after the failure were not compiled
    assert not list((tmp_path / "compiled").glob("*.so"))
