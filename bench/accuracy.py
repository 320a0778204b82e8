"""Refinement accuracy over simulated sessions, against the simulator's truth (issue 15).

``python -m bench.accuracy [default|faults|all] [--workers N]`` (not part of ``make bench``:
~40 identifications). Per session: the independent audit (:mod:`pipeline.rig.audit`, 1,000
configurations) of the thesis S-Model (``frames``) and of the refined signature (``chain``),
the predicted RMS (stage ``uncertainty``, scaled by the fitted noise) and the Cramér-Rao
bound of the refinement's own measurement model: the same propagation of ``(JᵀWJ)⁻¹``
without the χ²/dof scaling, i.e. the documented noise law (7.9) taken as true.

Sets: ``default`` robot1–7 (the committed recordings) and seeds 101–130 (default plan and
noise); ``faults`` seeds 11–20 with ``--faults bias`` and with ``--wac-error-cm 0.5``, each
against the same seed without the fault, and the fitted biases against the rig's.
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent


def _session(folder: Path, name: str, seed: int | None, **opts: Any) -> Path:
    from pipeline.rig.simulate import SimulationOptions, simulate_session

    d = folder / name
    if seed is None:  # a committed recording
        d.mkdir(parents=True)
        for f in ("recording.mcap", "rig-truth.json"):
            shutil.copy(ROOT / "sessions" / name / f, d / f)
    else:
        simulate_session(d, SimulationOptions(seed=seed, **opts))
    return d


def measure(folder: str, name: str, seed: int | None, opts: dict[str, Any]) -> dict[str, Any]:
    """Simulate (or copy), identify and audit one session; the numbers of one row."""
    from pipeline.identify import identify
    from pipeline.montecarlo.refine_study import session_accuracy
    from pipeline.rig.audit import read_truth
    from pipeline.stages.runner import stage_path
    from pipeline.stages.tables import read_table

    d = _session(Path(folder), name, seed, **opts)
    identify(d, report=False)
    acc = session_accuracy(d)  # the audit of `frames` and `chain`, as the refine study
    truth_doc = read_truth(d / "rig-truth.json")
    verdict = read_table(stage_path(d, "verdict")).to_pylist()[0]
    refine = read_table(stage_path(d, "refine")).to_pylist()
    fitted = {r["name"]: (r["value"], r["sigma"]) for r in refine if r["group"] == "bias"}
    true_bias = truth_doc.get("sensor", {}).get("mic_bias_cm", [0.0] * 4)
    z_bias = [
        abs(fitted[f"bias_{m}_cm"][0] - b) / fitted[f"bias_{m}_cm"][1]
        for m, b in zip("ABCD", true_bias, strict=True)
        if f"bias_{m}_cm" in fitted
    ]
    mics = {r["name"]: (r["value"], r["sigma"]) for r in refine if r["group"] == "mic"}
    a_true = truth_doc.get("sensor", {}).get("geometry_true", {}).get("microphones_cm", {})
    z_mic_a = [
        abs(mics[f"mic_A_{c}_cm"][0] - a_true["A"][k]) / mics[f"mic_A_{c}_cm"][1]
        for k, c in enumerate("xy")
        if f"mic_A_{c}_cm" in mics and "A" in a_true
    ]  # the gauge frame is the recorded one: C at 0, B on +Y, A in the X-Y plane
    return {
        "session": name,
        "thesis_cm": acc.smodel.rms_position_cm,
        "refined_cm": acc.refined.rms_position_cm,
        "predicted_cm": verdict["predicted_rms_cm"],
        "crb_cm": acc.crb_cm if verdict["predicted_rms_cm"] else None,
        "chi2_dof": acc.chi2_per_dof,
        "chi2_recorded_dof": verdict["chi2_recorded_per_dof"],
        "verdict": acc.verdict,
        "reasons": verdict["reasons"],
        "max_bias_z": max(z_bias) if z_bias else None,
        "max_mic_a_z": max(z_mic_a) if z_mic_a else None,
    }


def _jobs(which: str) -> list[tuple[str, int | None, dict[str, Any]]]:
    jobs: list[tuple[str, int | None, dict[str, Any]]] = []
    if which in ("default", "all"):
        jobs += [(f"robot{k}", None, {}) for k in range(1, 8)]
        jobs += [(f"seed{s}", s, {}) for s in range(101, 131)]
    if which in ("faults", "all"):
        for s in range(11, 21):
            jobs += [(f"clean{s}", s, {}), (f"bias{s}", s, {"faults": ("bias",)})]
            jobs += [(f"wac{s}", s, {"wac_error_cm": 0.5})]
    return jobs


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("which", nargs="?", default="all", choices=("default", "faults", "all"))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", type=Path, help="also write the rows here")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp, ProcessPoolExecutor(args.workers) as pool:
        futures = [pool.submit(measure, tmp, n, s, o) for n, s, o in _jobs(args.which)]
        rows = {r["session"]: r for r in (f.result() for f in futures)}
    for r in rows.values():
        print(
            f"{r['session']:>8}  thesis {r['thesis_cm']:.5f}  refined {r['refined_cm']:.5f}  "
            f"ratio {r['thesis_cm'] / r['refined_cm']:5.2f}  predicted {r['predicted_cm']:.5f}  "
            f"CRB {r['crb_cm']:.5f}  chi2/dof {r['chi2_dof']:.2f} "
            f"(recorded {r['chi2_recorded_dof']:.2f})  {r['verdict']}"
            + (f"  bias max z {r['max_bias_z']:.2f}" if r["max_bias_z"] is not None else "")
        )
    out: dict[str, Any] = {"rows": list(rows.values())}
    default = [r for n, r in rows.items() if n.startswith(("robot", "seed"))]
    if default:
        ratios = [r["thesis_cm"] / r["refined_cm"] for r in default]
        out["default"] = {
            "sessions": len(default),
            "refined_not_worse": sum(r["refined_cm"] <= r["thesis_cm"] for r in default),
            "median_ratio": statistics.median(ratios),
            "median_refined_over_crb": statistics.median(
                r["refined_cm"] / r["crb_cm"] for r in default
            ),
            "median_audited_over_predicted": statistics.median(
                r["refined_cm"] / r["predicted_cm"] for r in default
            ),
        }
    faults = [s for s in range(11, 21) if f"clean{s}" in rows]
    if faults:
        out["faults"] = {
            kind: {
                "rms_over_clean": [
                    rows[f"{kind}{s}"]["refined_cm"] / rows[f"clean{s}"]["refined_cm"]
                    for s in faults
                ],
                "verdicts": [rows[f"{kind}{s}"]["verdict"] for s in faults],
                "chi2_recorded_dof": [rows[f"{kind}{s}"]["chi2_recorded_dof"] for s in faults],
            }
            for kind in ("bias", "wac")
        }
        out["faults"]["bias"]["max_bias_z"] = [rows[f"bias{s}"]["max_bias_z"] for s in faults]
        out["faults"]["wac"]["max_mic_a_z"] = [rows[f"wac{s}"]["max_mic_a_z"] for s in faults]
    print(json.dumps({k: v for k, v in out.items() if k != "rows"}, indent=1))
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
