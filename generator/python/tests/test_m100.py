"""Issue 30's acceptance on the paper's M100 logs (../shared/flights/m100, beside the project; the
tests are skipped where it is absent): `uavgen.identify` writes the same model as `uavgen identify`
with the same options (scripts/identify_m100.sh's), and `uavgen.evaluate` equals
`uavgen evaluate --json` on the held-out run 7."""

import json

import pytest

import uavgen

from conftest import REPO

M100 = REPO.parent / "shared" / "flights" / "m100"
TRAIN = [M100 / f"m100_run{r}.csv" for r in (1, 2, 3, 4, 5)]

pytestmark = pytest.mark.skipif(not M100.is_dir(), reason=f"{M100} not found (the paper's logs sit beside the project)")

# scripts/identify_m100.sh's options, as CLI flags and as Python keywords.
OPTIONS = {
    "sindy": (["--sweep-values", "16,20,24,32,40,48,64"], {"sweep_values": [16, 20, 24, 32, 40, 48, 64]}),
    "pd": (["--targets", "integral"], {"targets": "integral"}),
}


@pytest.mark.parametrize("method", ["sindy", "pd"])
def test_identify_on_m100_runs_1_to_5_equals_cli(cli, tmp_path, method):
    flags, keywords = OPTIONS[method]
    cli_out, py_out = tmp_path / "cli" / f"m100_{method}.json", tmp_path / "py" / f"m100_{method}.json"
    cli_out.parent.mkdir()
    py_out.parent.mkdir()
    logs = [a for p in TRAIN for a in ("--log", p)]
    cli("identify", "--method", method, *logs, *flags, "--out", cli_out)
    model = uavgen.identify([uavgen.read_log(p) for p in TRAIN], method=method, out=py_out, **keywords)
    # The provenance names the logs (the same paths) and the tool (the same library): the files are
    # identical byte for byte.
    assert py_out.read_bytes() == cli_out.read_bytes()
    assert model.kind == method
    # evaluate on the held-out run 7, both front ends (the same model file).
    run7 = M100 / "m100_run7.csv"
    cli("evaluate", "--model", cli_out, "--log", run7, "--json", tmp_path / "cli_eval.json")
    got = uavgen.evaluate(uavgen.Model.load(cli_out), [uavgen.read_log(run7)])
    assert got == json.loads((tmp_path / "cli_eval.json").read_text())
