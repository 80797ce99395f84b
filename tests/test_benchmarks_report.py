"""docs/benchmarks.md is what benchmarks/report.py renders from benchmarks/results/*.json, and
the results files name the command, date and machine behind every figure."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _load(name: str):
    spec = importlib.util.spec_from_file_location(f"bench_{name}", ROOT / "benchmarks" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses look their module up there
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def report():
    return _load("report")


@pytest.fixture(scope="module")
def results():
    return _load("_results")


def test_docs_page_matches_the_results_files(report):
    assert report.main(["--check"]) == 0, "run `python benchmarks/report.py` and commit docs/benchmarks.md"


def test_every_results_file_is_shown_and_says_how_it_was_made(report):
    shown = {s.name for s in report.SECTIONS}
    for path in sorted((ROOT / "benchmarks" / "results").glob("*.json")):
        assert path.stem in shown, f"{path.name}: no section of benchmarks/report.py shows it"
        m = json.loads(path.read_text())["measured"]
        # benchmarks/NAME.py writes NAME.json; a second figure set of one script, NAME_PART.json
        python, script = m["command"].split()[:2]
        assert python == "python" and script.startswith("benchmarks/"), path.name
        assert (ROOT / script).is_file() and path.stem.startswith(Path(script).stem), path.name
        assert "/tmp" not in m["command"], f"{path.name}: a scratch path in its command"
        assert m["date"] and m["machine"]["summary"], path.name


def test_the_command_shown_leaves_out_where_files_were_written(results):
    assert results._without_out(["10", "--out", "/tmp/x.json", "--log=/tmp/l", "--jobs", "2"]) \
        == ["10", "--jobs", "2"]


def test_a_benchmark_not_run_yet_gives_its_command_not_a_number(report, tmp_path):
    text = report.render(tmp_path)
    for s in report.SECTIONS:
        assert f"Not measured yet: run `{s.command}`" in text.replace("\n", " ")
    assert "| mask IoU blade / tower / nacelle | not measured yet |" in text


def test_save_then_render(report, results, tmp_path, monkeypatch):
    fig = {"speed": {}, "synthetic": {}}
    doc = json.loads((ROOT / "benchmarks" / "results" / "segment_accuracy.json").read_text())
    for k in ("speed", "synthetic", "real"):
        fig[k] = doc[k]
    monkeypatch.setattr(sys, "argv", ["pytest"])
    path = results.save("segment_accuracy", fig, argv=["--n", "3"], out=tmp_path / "segment_accuracy.json")
    saved = json.loads(path.read_text())
    assert saved["schema"] == "wtinspect.benchmark.segment_accuracy"
    assert saved["measured"]["command"] == "python benchmarks/segment_accuracy.py --n 3"
    assert saved["measured"]["machine"]["cores"] >= 1
    text = report.render(tmp_path)
    assert "by `python benchmarks/segment_accuracy.py --n 3`" in text.replace("\n", " ")
    assert "| mask IoU blade / tower / nacelle | 0.850 / 0.906 / 0.828 |" in text


def test_a_results_file_without_a_shown_figure_is_an_error(report, results, tmp_path, capsys):
    results.save("plan_property", {"summary": {"planned": 3}}, argv=[], out=tmp_path / "plan_property.json")
    with pytest.raises(report.ReportError, match=r"plan_property.json: no `summary.plan_errors`"):
        report.render(tmp_path)
    assert report.main(["--check", "--no-blocks", "--results", str(tmp_path),
                        "--out", str(tmp_path / "x.md")]) == 3
    assert "summary.plan_errors" in capsys.readouterr().err


def test_check_fails_on_a_stale_page(report, tmp_path):
    page = tmp_path / "benchmarks.md"
    stale = report.render().replace("| 0.850 / 0.906 / 0.828 |", "| 0.860 / 0.906 / 0.828 |")
    assert stale != report.render()
    page.write_text(stale)
    assert report.main(["--check", "--no-blocks", "--out", str(page)]) == 1
    assert report.main(["--no-blocks", "--out", str(page)]) == 0
    assert report.main(["--check", "--no-blocks", "--out", str(page)]) == 0


def test_the_model_cards_figures_are_rendered_too(report, tmp_path):
    card = (ROOT / "models" / "README.md").read_text()
    block = card[card.index(report.BEGIN):card.index(report.END)]
    assert "| held-out renders | mask IoU blade / tower / nacelle | 0.850 / 0.906 / 0.828 |" in block
    assert report.with_blocks(card, report.BLOCKS["models/README.md"], "models/README.md") == card
    stale = card.replace("| 0.850 / 0.906 / 0.828 |", "| 0.854 / 0.914 / 0.834 |")
    assert stale != card
    assert report.with_blocks(stale, report.BLOCKS["models/README.md"], "models/README.md") == card
    with pytest.raises(report.ReportError, match="no rendered-figures block"):
        report.with_blocks("# a page\n", ("Segmentation: speed",), "x.md")


def test_save_refuses_a_measured_key(results, tmp_path):
    with pytest.raises(ValueError, match="measured"):
        results.save("x", {"measured": 1}, argv=[], out=tmp_path / "x.json")


def test_the_readmes_figures_are_the_benchmark_pages():
    """The README quotes a few headline figures; each must be on docs/benchmarks.md as it is."""
    import re

    readme = (ROOT / "README.md").read_text()
    start = readme.index("The shipped segmentation model")
    quoted = readme[start:readme.index("`docs/benchmarks.md`", start)]
    page = (ROOT / "docs" / "benchmarks.md").read_text()
    figures = re.findall(r"\d+\.\d+", quoted)
    assert len(figures) >= 5, quoted
    missing = [f for f in figures if f not in page]
    assert not missing, f"README.md quotes {missing}, not on docs/benchmarks.md"


def test_a_subset_or_another_model_never_overwrites_the_real_photo_figures(capsys):
    seg_real = _load("segment_real")
    before = (ROOT / "benchmarks" / "results" / "segment_real.json").read_bytes()
    for argv in (["--limit", "2"], ["--only", "other"], ["--model", "some.pt"], ["--no-refine"],
                 ["--refiner", "some.pt"]):
        with pytest.raises(SystemExit) as e:
            seg_real.main(argv)
        assert e.value.code == 2, argv
        assert "--out FILE is needed" in capsys.readouterr().err
    assert (ROOT / "benchmarks" / "results" / "segment_real.json").read_bytes() == before


def test_segment_accuracy_knows_a_model_that_learned_the_real_photos(tmp_path):
    from wtcli.segment.infer import load_model
    from wtcli.segment.model import build_model, save_weights

    seg_acc = _load("segment_accuracy")
    net = build_model()
    save_weights(net, tmp_path / "r.pt", {"real": "../shared/real-photos", "real_holdout": []})
    save_weights(net, tmp_path / "s.pt", {"data": "synthetic"})
    assert seg_acc._trained_on_real(load_model(tmp_path / "r.pt", "cpu", "fp32")) == "../shared/real-photos"
    assert seg_acc._trained_on_real(load_model(tmp_path / "s.pt", "cpu", "fp32")) is None


def test_segment_real_refuses_a_refiner_that_learned_the_fold(tmp_path, capsys):
    """A refiner fine-tuned on photos (train-refiner --real) is held to what a segmenter is: it
    may refine only the folds it held out, and the fold refiners need fold runs."""
    from wtcli.segment.refine import Refiner, save_refiner

    seg_real = _load("segment_real")
    save_refiner(Refiner((8, 4)), tmp_path / "ref.pt",
                 {"real": "../shared/real-photos", "real_holdout": ["envB_34-41"]})
    seg_real.check_not_trained_on(tmp_path / "ref.pt", "envB_34-41")
    with pytest.raises(SystemExit, match="without holding out sequence other"):
        seg_real.check_not_trained_on(tmp_path / "ref.pt", "other")
    for argv in (["--fold-refiners", "--out", "x.json"],
                 ["--runs", "r", "--fold-refiners", "--no-refine", "--out", "x.json"]):
        with pytest.raises(SystemExit) as e:
            seg_real.main(argv)
        assert e.value.code == 2 and "--fold-refiners" in capsys.readouterr().err


def test_segment_real_grows_each_part_by_one_pixel_in_the_class_maps_order():
    """The diagnostic beside the real-photo IoU: every part's region one pixel wider (3 x 3), a
    part painted over the one before it in the class map's order, as segment paints them."""
    import numpy as np

    seg_real = _load("segment_real")
    cmap = np.zeros((9, 9), np.uint8)
    cmap[1:8, 2] = 1      # a blade one pixel wide
    cmap[1:8, 5] = 2      # a tower two pixels to its right
    cmap[4, 7] = 3        # a nacelle pixel beside the tower
    g = seg_real.grown(cmap)
    assert list(g[4]) == [0, 1, 1, 1, 2, 2, 3, 3, 3]   # the nacelle over the grown tower
    assert g[0, 1] == 1 and g[8, 3] == 1 and g[0, 0] == 0   # corners grow too, no further
    assert not seg_real.grown(np.zeros_like(cmap)).any()   # nothing grows from nothing
    assert ((g == 1).sum(), (cmap == 1).sum()) == (27, 7)


def test_outline_tint_tells_a_drawn_margin_from_a_soft_edge():
    """A truth drawn a pixel outside a sharp blade: the pixels it adds look like the background
    (share 0); the same margin over a blurred edge carries half the blade's contrast."""
    import numpy as np

    seg_real = _load("segment_real")
    img = np.full((40, 40, 3), 50, np.uint8)
    img[5:35, 10:20] = 200
    pred = np.zeros((40, 40), bool)
    pred[5:35, 10:20] = True
    truth = np.zeros_like(pred)
    truth[5:35, 9:21] = True
    t = seg_real.outline_tint(img, truth, pred)
    assert t["missed"].size and np.allclose(t["missed"], 0.0)
    assert np.allclose(np.median(t["edge"]), 1.0) and np.allclose(np.median(t["beyond"]), 0.0)
    img[5:35, [9, 20]] = 125
    soft = seg_real.outline_tint(img, truth, pred)
    assert np.allclose(soft["missed"], 0.5)
    s = seg_real.tint_summary([t, soft])
    assert s["missed"]["pixels"] == t["missed"].size + soft["missed"].size
    assert s["missed"]["p25"] == 0.0 and s["missed"]["p75"] == 0.5
