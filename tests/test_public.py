"""``python -m tactile_exp.data public import|list``: each recipe on tiny files in its upstream's
own layout -> the folder layout (labels, declared split, frozen folds), and its one-line
refusals: files that do not match (count, checksum), a missing label table, an unknown name."""

from __future__ import annotations

import shutil
import tarfile
from pathlib import Path

import numpy as np
import pytest
import yaml
from phac2_fixture import OBJECTS, write_file
from public_fixture import icub_values, pinned_recipe, write_biotac, write_bolt, write_icub

from tactile_exp.data.__main__ import main as data_main
from tactile_exp.data.folder import FolderDataSet
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.data.public import PROVENANCE
from tactile_exp.data.recipe import FOLDS_DIR, RECIPE_DIR, RECIPES
from tactile_exp.data.splits import make_split


def _import(capsys, name: str, src: Path | str, dst: Path) -> tuple[int, list[str], list[str]]:
    code = data_main(["public", "import", name, "--from", str(src), str(dst)])
    captured = capsys.readouterr()
    return code, captured.out.splitlines(), captured.err.splitlines()


def test_icub_grasp_is_imported_with_its_labels_split_and_frozen_folds(tmp_path, capsys) -> None:
    src = write_icub(tmp_path / "clone")
    recipe = pinned_recipe("icub_grasp", src, tmp_path / "icub_grasp.yaml")
    code, out, err = _import(capsys, str(recipe), src, tmp_path / "ds")
    assert (code, err) == (0, [])
    assert out[0] == f"wrote {tmp_path / 'ds'} (data=folder data.path={tmp_path / 'ds'})"
    assert "  files     200 (" in out[2] and out[2].endswith("sha256 matches")
    assert out[4] == "  trials    200 (20-20 per object)"
    ds = FolderDataSet(tmp_path / "ds")
    assert len(ds.object_ids()) == 10 and len(ds.trials) == 200
    assert "full_coke" not in {ds.object_name(i) for i in ds.object_ids()}
    assert len(ds.sensor.channels) == 69 and ds.sensor.channels[:2] == ("joint07", "joint08")
    # book is the 8th object: trial 10 is its 10th trial; line 2 of a slice (derived) left out
    book = next(i for i in ds.object_ids() if ds.object_name(i) == "book")
    arr = ds.signals(f"book_{book:03d}_10")
    want = [[v for j, row in enumerate(icub_values(7, 10, k)) if j != 1 for v in row]
            for k in range(2)]  # fmt: skip
    np.testing.assert_allclose(arr, np.array(want).T)
    labels = {ds.object_name(i): v for i, v in ds.labels().items()}
    assert [o for o, v in labels.items() if v["soft"]] == ["blue_bear", "monkey_toy"]
    assert ds.declared_split == {"name": "folds", "folds": 2}
    shipped = (FOLDS_DIR / "icub_grasp.yaml").read_bytes()
    assert (tmp_path / "ds" / "folds.yaml").read_bytes() == shipped
    assert "Copyright 2012 Harold Soh" in (tmp_path / "ds" / PROVENANCE).read_text()
    # split=folds reads the frozen folds: fold f of seed s tests exactly the file's objects
    folds = ds.frozen_folds
    assert folds is not None
    for seed in (0, 3):
        tested = []
        for fold in (0, 1):
            split = make_split(ds, "can", "folds", seed, folds=2, fold=fold, frozen=folds.digest)
            objects = sorted(ds.object_name(i) for i in split.objects("test"))
            assert objects == sorted(folds.labels["can"][seed][fold])
            tested += objects
        assert sorted(tested) == sorted(labels)
    # a notebook's make_split without the digest reads the folds the data set holds
    held = make_split(ds, "can", "folds", 3, folds=2, fold=1)
    assert held == make_split(ds, "can", "folds", 3, folds=2, fold=1, frozen=folds.digest)
    assert make_split(ds, "can", "declared", 3) == make_split(ds, "can", "folds", 3, folds=2)


def test_biotac_slide_reads_the_bio_csv_of_each_slide(tmp_path, capsys) -> None:
    src = write_biotac(tmp_path / "clone")
    recipe = pinned_recipe("biotac_slide", src, tmp_path / "biotac_slide.yaml")
    code, out, err = _import(capsys, str(recipe), src, tmp_path / "ds")
    assert (code, err) == (0, [])
    ds = FolderDataSet(tmp_path / "ds")
    assert len(ds.trials) == 1000 and ds.sensor.channels[:4] == ("tdc", "tac", "pdc", "pac1")
    mat12 = next(i for i in ds.object_ids() if ds.object_name(i) == "mat12")
    arr = ds.signals(f"mat12_{mat12:03d}_07")  # slide 7 of mat12: values m + n + k + column
    np.testing.assert_allclose(arr[:, 0], 12 + 7 + np.arange(44))
    assert ds.declared_split == {"name": "folds", "folds": 5}


def test_penn_bolt_reads_every_trial_group_of_each_objects_file(tmp_path, capsys) -> None:
    src = write_bolt(tmp_path / "clone")
    recipe = pinned_recipe("penn_bolt", src, tmp_path / "penn_bolt.yaml")
    code, out, err = _import(capsys, str(recipe), src, tmp_path / "ds")
    assert (code, err) == (0, [])
    assert out[4] == "  trials    10 (2-2 per object)"
    ds = FolderDataSet(tmp_path / "ds")
    cork = next(i for i in ds.object_ids() if ds.object_name(i) == "cork")  # object 1: base 1000
    arr = ds.signals(f"cork_{cork:03d}_02")
    assert arr.shape == (88, 6)
    first = [1201, 1202, 1203, *range(1204, 1226), *range(1230, 1249)]  # finger_0, trial 2
    np.testing.assert_allclose(arr[:44, 0], first)
    np.testing.assert_allclose(arr[44:, 0], np.array(first) + 50)


def test_phac2_is_checked_by_its_reader_and_copied(tmp_path, capsys) -> None:
    src = tmp_path / "release"
    src.mkdir()
    write_file(src / "phac_train_test_pos_neg_90_10_1_20.h5", tuple(OBJECTS), 10, signals=False)
    code, out, err = _import(capsys, "phac2", src, tmp_path / "ds")
    assert (code, err) == (0, [])
    copied = tmp_path / "ds" / "phac_train_test_pos_neg_90_10_1_20.h5"
    assert out[0] == f"wrote {tmp_path / 'ds'} (data=phac2 data.path={copied})"
    assert out[2].endswith("counts only")
    assert len(PHAC2(copied).trials) == 600
    few = tmp_path / "few"
    few.mkdir()
    write_file(few / "phac_train_test_pos_neg_90_10_1_20.h5", tuple(OBJECTS)[:5], 2, False)
    code, _, err = _import(capsys, "phac2", few, tmp_path / "ds2")
    assert code == 1 and len(err) == 1
    assert "5 objects and 10 trials, expected the release's 60 and 600" in err[0]


def test_an_archive_of_the_upstream_imports_as_its_folder_does(tmp_path, capsys) -> None:
    src = write_bolt(tmp_path / "Penn-haptics-bolt-441c64d")
    recipe = pinned_recipe("penn_bolt", src, tmp_path / "penn_bolt.yaml")
    archive = tmp_path / "bolt.tar.gz"
    with tarfile.open(archive, "w:gz") as t:
        t.add(src, arcname=src.name)  # GitHub's archives hold one top folder
    code, _, err = _import(capsys, str(recipe), archive, tmp_path / "ds")
    assert (code, err) == (0, [])
    assert len(FolderDataSet(tmp_path / "ds").trials) == 10


def test_a_url_downloads_the_archive_and_imports_it(tmp_path, capsys) -> None:
    """With a network ``--from URL`` works as the archive does (here a local HTTP server); an
    unreachable one is one line."""
    import functools
    import http.server
    import threading

    src = write_bolt(tmp_path / "Penn-haptics-bolt-441c64d")
    recipe = pinned_recipe("penn_bolt", src, tmp_path / "penn_bolt.yaml")
    served = tmp_path / "served"
    served.mkdir()
    with tarfile.open(served / "bolt.tar.gz", "w:gz") as t:
        t.add(src, arcname=src.name)

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *args: object) -> None:  # stderr is the import's
            pass

    handler = functools.partial(Quiet, directory=str(served))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        url = f"http://127.0.0.1:{server.server_port}/bolt.tar.gz"
        code, out, err = _import(capsys, str(recipe), url, tmp_path / "ds")
        assert code == 0 and err[0] == f"downloading {url}" and err[1].startswith("downloaded ")
        assert len(FolderDataSet(tmp_path / "ds").trials) == 10
        code, _, err = _import(capsys, str(recipe), url.replace("bolt", "nope"), tmp_path / "d2")
        assert code == 1 and err[-1].startswith(f"error: {url.replace('bolt', 'nope')}: cannot ")
    finally:
        server.shutdown()


def test_without_from_the_pinned_archive_is_the_source(tmp_path) -> None:
    from tactile_exp.data.public import archive_url

    assert archive_url(RECIPES.build("icub_grasp")) == (
        "https://github.com/clear-nus/icub_grasp_dataset/archive/"
        "87dceecaa2f8056025f2ad42b55cb5f46fb77229.tar.gz"
    )
    with pytest.raises(Exception, match="is no repository to download from; give --from"):
        archive_url(RECIPES.build("phac2"))


def _no_labels(tmp_path: Path) -> str:
    node = yaml.safe_load((RECIPE_DIR / "penn_bolt.yaml").read_text())
    del node["labels"]
    (tmp_path / "mine.yaml").write_text(yaml.safe_dump(node))
    return str(tmp_path / "mine.yaml")


@pytest.mark.parametrize(
    "case,expected",
    [
        ("unknown", "error: unknown public data set 'nope'; known: biotac_slide, icub_grasp, "),
        ("count", "error: {src}: 199 files match recipe icub_grasp ("),
        ("checksum", "error: {src}: the 200 files of recipe icub_grasp have sha256 "),
        ("labels", "error: {tmp}/mine.yaml: no label table (labels: label -> {{source: "),
        ("file", "error: {src}/iCubGraspDataset/book_3.txt:3: 4 values, expected 5"),
        ("src", "error: {tmp}/nowhere: no such folder or archive; expected the upstream's "),
    ],
)
def test_each_refusal_is_one_error_line(tmp_path, capsys, case, expected) -> None:
    src = write_icub(tmp_path / "clone")
    name = str(pinned_recipe("icub_grasp", src, tmp_path / "icub_grasp.yaml"))
    if case == "unknown":
        name = "nope"
    if case == "count":
        (src / "iCubGraspDataset" / "lotion_20.txt").unlink()
        name = "icub_grasp"
    if case == "checksum":
        name = "icub_grasp"  # the real files' checksum; these are tiny copies
    if case == "labels":
        name = _no_labels(tmp_path)
    if case == "file":
        file = src / "iCubGraspDataset" / "book_3.txt"
        lines = file.read_text().splitlines()
        lines[2] = "1 2 3 4"  # a slice's second line: five values
        file.write_text("\n".join(lines))
        name = str(pinned_recipe("icub_grasp", src, tmp_path / "icub_grasp.yaml"))
    if case == "src":
        src = tmp_path / "nowhere"
    code, out, err = _import(capsys, name, src, tmp_path / "ds")
    assert code == 1 and out == [] and len(err) == 1
    assert err[0].startswith(expected.format(src=src, tmp=tmp_path)), err[0]
    assert not (tmp_path / "ds").exists()  # nothing written before every check passed


def test_list_names_each_upstream_its_commit_and_licence(capsys) -> None:
    assert data_main(["public", "list"]) == 0
    out = capsys.readouterr().out
    for name in ("phac2", "penn_bolt", "biotac_slide", "icub_grasp"):
        recipe = RECIPES.build(name)
        assert f"{name}: {recipe.title}\n" in out
        assert f"  licence   {recipe.licence}\n" in out
    commit = "87dceecaa2f8056025f2ad42b55cb5f46fb77229"
    assert f"upstream  github.com/clear-nus/icub_grasp_dataset at {commit}\n" in out
    assert "labels    foam, hard, rough (ours: foam, hard, rough)" in out
    assert "labels    thick, rough, smooth, textile (ours: textile)" in out


def test_a_changed_split_file_makes_another_job(tmp_path, capsys, compose_config) -> None:
    from tactile_exp.config import settings_from_config

    src = write_bolt(tmp_path / "clone")
    recipe = pinned_recipe("penn_bolt", src, tmp_path / "penn_bolt.yaml")
    assert _import(capsys, str(recipe), src, tmp_path / "ds")[0] == 0
    overrides = ["data=folder", f"data.path={tmp_path / 'ds'}", "modality=signals", "model=linear"]
    before = settings_from_config(compose_config(overrides))
    assert before.split_params["frozen"] == FolderDataSet(tmp_path / "ds").frozen_folds.digest
    explicit = settings_from_config(compose_config([*overrides, "split=folds", "split.folds=2"]))
    assert explicit.config_hash == before.config_hash  # split=folds reads the same frozen folds
    folds = tmp_path / "ds" / "folds.yaml"
    node = yaml.safe_load(folds.read_text())
    node["labels"]["foam"][0].reverse()  # seed 0's folds of foam swapped
    folds.write_text(yaml.safe_dump(node))
    after = settings_from_config(compose_config(overrides))
    assert after.config_hash != before.config_hash
    # a job configured before the change refuses to run on the changed file
    ds = FolderDataSet(tmp_path / "ds")
    with pytest.raises(Exception, match="its folds file changed since the job was configured"):
        make_split(ds, "foam", "folds", 0, **before.split_params)
    shutil.rmtree(tmp_path / "ds")
