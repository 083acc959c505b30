"""``python -m tactile_exp.data public list|import NAME --from SRC DST``: public data sets by
recipe (`tactile_exp.data.recipe`, read by `tactile_exp.data.readers`) -> the folder layout.

``SRC`` is a local clone or copy of the upstream (a folder) or an archive of one (``.zip``,
``.tar``, ``.tar.gz``, ``.tgz``), or with a network its URL; without ``--from`` the upstream's
archive at the pinned commit is downloaded (`archive_url`). The recipe's files are found under
it by their pattern, counted and checksummed (`tree_sha256`) against the recipe, and refused in
one line when they differ; then read (the recipe's reader) and written as the folder layout with
the recipe's label table, its declared split and its frozen folds (``folds.yaml``), so that
``data=folder data.path=DST`` and ``split=declared`` run on it unchanged. PHAC-2 is not
converted: its file is checked with the existing reader and copied, for ``data=phac2``.
"""

from __future__ import annotations

import hashlib
import shutil
import sys
import tarfile
import tempfile
import urllib.error
import urllib.request
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tactile_exp.data.dataset import Sensor
from tactile_exp.data.folder import FolderDataSet, write_folder
from tactile_exp.data.frozen import FrozenFolds, check_stratified, deal
from tactile_exp.data.layout import DataError
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.data.readers import READERS
from tactile_exp.data.recipe import FOLDS_DIR, RECIPES, Recipe, find

ARCHIVES = (".zip", ".tar", ".tar.gz", ".tgz")
PROVENANCE = "UPSTREAM.txt"  # written into DST: where the data came from, its licence
PHAC2_OBJECTS, PHAC2_TRIALS = 60, 600  # the release's objects and trials (10 per object)
DOWNLOAD_TIMEOUT = 60  # seconds without an answer before a download is given up


def tree_sha256(root: Path, files: list[Path]) -> str:
    """One checksum of ``files`` (under ``root``): their paths and contents, in path order."""
    h = hashlib.sha256()
    for file in sorted(files, key=lambda p: p.relative_to(root).as_posix()):
        h.update(f"{file.relative_to(root).as_posix()}\0".encode())
        h.update(hashlib.sha256(file.read_bytes()).digest())
    return h.hexdigest()


def archive_url(recipe: Recipe) -> str:
    """The upstream's archive at the pinned commit (GitHub's), what ``public import`` without
    ``--from`` downloads."""
    up = recipe.upstream
    if "repository" not in up or "commit" not in up:
        raise DataError(
            f"recipe {recipe.name}: its upstream ({recipe.where()}) is no repository to download "
            "from; give --from with a local copy"
        )
    return f"https://github.com/{up['repository']}/archive/{up['commit']}.tar.gz"


def download(url: str, folder: Path) -> Path:
    """``url`` saved into ``folder`` (its last path segment as the name); one DataError line
    when it cannot be fetched."""
    name = url.rstrip("/").rsplit("/", 1)[-1] or "download"
    target = folder / name
    print(f"downloading {url}", file=sys.stderr, flush=True)
    try:
        with (
            urllib.request.urlopen(url, timeout=DOWNLOAD_TIMEOUT) as answer,
            open(target, "wb") as f,
        ):
            shutil.copyfileobj(answer, f)
    except (urllib.error.URLError, OSError, ValueError) as err:
        reason = getattr(err, "reason", err)
        raise DataError(
            f"{url}: cannot download ({reason}); without a network give --from a local clone, "
            "folder or archive"
        ) from None
    print(f"downloaded {target.stat().st_size / 1e6:.1f} MB", file=sys.stderr, flush=True)
    return target


@contextmanager
def fetched(src: str | Path | None, recipe: Recipe) -> Iterator[Path]:
    """The folder of the upstream's files: ``src`` (a folder or archive), or downloaded from a
    URL, or (None) from the recipe's pinned archive."""
    url = archive_url(recipe) if src is None else str(src)
    if not url.startswith(("http://", "https://")):
        with opened(Path(url).expanduser()) as root:
            yield root
        return
    with (
        tempfile.TemporaryDirectory(prefix="tactile_exp_download_") as tmp,
        opened(download(url, Path(tmp))) as root,
    ):
        yield root


@contextmanager
def opened(src: Path) -> Iterator[Path]:
    """The folder ``src`` is, or the folder an archive unpacks to (its single top folder, as
    GitHub's archives have, else the archive's root)."""
    if src.is_dir():
        yield src
        return
    if not src.is_file() or not src.name.endswith(ARCHIVES):
        raise DataError(
            f"{src}: no such folder or archive; expected the upstream's clone or folder, or an "
            f"archive of it ({', '.join(ARCHIVES)})"
        )
    with tempfile.TemporaryDirectory(prefix="tactile_exp_public_") as tmp:
        try:
            if src.name.endswith(".zip"):
                with zipfile.ZipFile(src) as z:
                    z.extractall(tmp)
            else:
                with tarfile.open(src) as t:
                    t.extractall(tmp, filter="data")
        except (OSError, zipfile.BadZipFile, tarfile.TarError) as err:
            raise DataError(f"{src}: cannot unpack ({err})") from None
        entries = list(Path(tmp).iterdir())
        yield entries[0] if len(entries) == 1 and entries[0].is_dir() else Path(tmp)


def select(recipe: Recipe, root: Path) -> dict[str, list[Path]]:
    """Object -> its trial files (trial order) under ``root``: the files matching the recipe's
    pattern whose object it lists (and whose trial number it takes)."""
    out: dict[str, list[tuple[int, str, Path]]] = {}
    for file in root.rglob("*"):
        rel = file.relative_to(root).as_posix()
        m = recipe.files.fullmatch(rel)
        if m is None or not file.is_file():
            continue
        if recipe.objects and m.group("object") not in recipe.objects:
            continue
        trial = int(m.group("trial")) if "trial" in recipe.files.groupindex else 0
        if recipe.trials is not None and not recipe.trials[0] <= trial <= recipe.trials[1]:
            continue
        out.setdefault(m.group("object"), []).append((trial, rel, file))
    order = list(recipe.objects) or sorted(out)
    return {o: [f for _, _, f in sorted(out[o])] for o in order if o in out}


def check_files(recipe: Recipe, root: Path, files: dict[str, list[Path]]) -> None:
    """The recipe's count and checksum, or one `DataError` saying what differs."""
    found = sum(len(f) for f in files.values())
    upstream = f"the upstream {recipe.where()}"
    if found != recipe.count:
        missing = [o for o in recipe.objects if o not in files]
        also = f" (no files of {missing[:5]})" if missing else ""
        raise DataError(
            f"{root}: {found} files match recipe {recipe.name} ({recipe.files.pattern}), "
            f"expected {recipe.count}{also}; expected {upstream}"
        )
    if recipe.sha256 is not None:
        got = tree_sha256(root, [f for fs in files.values() for f in fs])
        if got != recipe.sha256:
            raise DataError(
                f"{root}: the {found} files of recipe {recipe.name} have sha256 {got[:12]}..., "
                f"the recipe's is {recipe.sha256[:12]}...: not {upstream}, or modified"
            )


@dataclass
class PublicImport:
    """What ``import_public`` found and wrote."""

    recipe: Recipe
    path: Path
    data: str  # the overrides that run on it
    trials: dict[str, int]  # object -> trials
    samples: list[int]
    checked: str  # "sha256 matches" | "counts only"

    def summary(self) -> list[str]:
        r = self.recipe
        lines = [
            f"wrote {self.path} ({self.data})",
            f"  upstream  {r.title}: {r.where()}",
            f"  files     {r.count} ({r.files.pattern}), {self.checked}",
            f"  objects   {len(self.trials)}: {', '.join(self.trials)}",
            f"  trials    {sum(self.trials.values())} ({min(self.trials.values())}-"
            f"{max(self.trials.values())} per object)",
        ]
        if self.samples:
            lines.append(
                f"  samples   {min(self.samples)}-{max(self.samples)} per trial "
                f"(median {int(np.median(self.samples))})"
            )
        lines += [
            f"  channels  {len(r.channels) or r.described and r.described['channels']}, "
            f"rate {r.rate_hz:g} Hz ({r.rate_source})",
            f"  split     {_split(r)}: what split=declared runs",
            f"  licence   {r.licence}",
        ]
        return lines


def import_public(name: str, src: str | Path | None, dst: str | Path) -> PublicImport:
    """Check the upstream's files under ``src`` (`fetched`) against recipe ``name`` and write
    ``dst``."""
    recipe = find(name)
    dst = Path(dst).expanduser()
    if dst.exists() and (not dst.is_dir() or any(dst.iterdir())):
        raise DataError(f"{dst}: exists and is not an empty folder; expected a new folder")
    with fetched(src, recipe) as root:
        files = select(recipe, root)
        check_files(recipe, root, files)
        if recipe.described is not None:
            return _copy_phac2(recipe, files, dst)
        if recipe.reader not in READERS:
            known = ", ".join(READERS.names())
            raise DataError(f"{recipe.file}: reader: unknown {recipe.reader!r}; known: {known}")
        read = READERS[recipe.reader]
        trials = {o: [a for f in fs for a in read(f, recipe.channels)] for o, fs in files.items()}
    table = recipe.label_table()
    folds = recipe.frozen_folds()
    problems = check_stratified(folds, table)
    if problems or folds.folds != recipe.folds or set(folds.labels) != set(recipe.labels):
        raise DataError(
            f"{recipe.file}: its frozen folds do not fit its label table "
            f"({problems[:1] or 'labels or K differ'}); regenerate them (public freeze)"
        )
    sensor = Sensor(recipe.sensor, recipe.channels, recipe.rate_hz)
    write_folder(
        dst, sensor, table, trials, split={"name": "folds", "folds": recipe.folds}, frozen=folds
    )
    (dst / PROVENANCE).write_text(provenance(recipe))
    FolderDataSet(dst)  # what data=folder will read, checked once
    return PublicImport(
        recipe,
        dst,
        f"data=folder data.path={dst}",
        {o: len(t) for o, t in trials.items()},
        [a.shape[1] for t in trials.values() for a in t],
        "sha256 matches" if recipe.sha256 else "counts only",
    )


def _copy_phac2(recipe: Recipe, files: dict[str, list[Path]], dst: Path) -> PublicImport:
    """PHAC-2 as it is: the release file checked by the existing reader and copied to ``dst``."""
    (file,) = [f for fs in files.values() for f in fs]
    dataset = PHAC2(file)
    objects, trials = len(dataset.object_ids()), len(dataset.trials)
    if (objects, trials) != (PHAC2_OBJECTS, PHAC2_TRIALS):
        raise DataError(
            f"{file}: {objects} objects and {trials} trials, expected the release's "
            f"{PHAC2_OBJECTS} and {PHAC2_TRIALS}"
        )
    dst.mkdir(parents=True, exist_ok=True)
    shutil.copy2(file, dst / file.name)
    (dst / PROVENANCE).write_text(provenance(recipe))
    per_object: dict[str, int] = {}
    for t in dataset.trials:
        key = dataset.object_name(t.object_id)
        per_object[key] = per_object.get(key, 0) + 1
    checked = "sha256 matches" if recipe.sha256 else "counts only"
    return PublicImport(
        recipe, dst, f"data=phac2 data.path={dst / file.name}", per_object, [], checked
    )


def freeze(recipe: Recipe) -> Path:
    """(Re)write the recipe's frozen folds from its label table (`tactile_exp.data.frozen.deal`):
    what ships in ``frozen_folds/<name>.yaml``; a test checks the shipped file equals this."""
    folds = FrozenFolds(
        recipe.folds, recipe.resamples, deal(recipe.label_table(), recipe.folds, recipe.resamples)
    )
    file = FOLDS_DIR / f"{recipe.name}.yaml"
    folds.write(file)
    return file


def provenance(recipe: Recipe) -> str:
    """What an imported data set keeps of where it came from: upstream, licence, labels."""
    lines = [
        f"{recipe.title} ({recipe.name}), imported by tactile_exp's public recipe.",
        f"Upstream: {recipe.where()}",
        f"Holds: {recipe.holds}",
        f"Licence (as the upstream states it): {recipe.licence}",
        "Labels:",
        *(f"  {a}: {spec.source}: {spec.origin}" for a, spec in recipe.labels.items()),
    ]
    return "\n".join(lines) + "\n"


def listing() -> list[str]:
    """``public list``: every recipe, what it declares."""
    lines = []
    for name in RECIPES.names():
        r = RECIPES.build(name)
        ours = sorted(a for a, s in r.labels.items() if s.source == "ours")
        words = r.described or {}
        labels = words.get("labels") or ", ".join(r.labels) + (
            f" (ours: {', '.join(ours)})" if ours else ""
        )
        signals = words.get("channels") or f"{len(r.channels)} channels"
        lines += [
            f"{name}: {r.title}",
            f"  upstream  {r.where()}",
            f"  holds     {r.holds}",
            f"  licence   {r.licence}",
            f"  files     {r.count} ({r.files.pattern}; reader {r.reader}), "
            f"{'sha256 ' + r.sha256[:12] + '...' if r.sha256 else 'counts only'}",
            f"  signals   {signals} at {r.rate_hz:g} Hz ({r.rate_source})",
            f"  objects   {words.get('objects') or len(r.objects)}",
            f"  labels    {labels}",
            f"  split     {_split(r)}",
        ]
    return lines


def _split(recipe: Recipe) -> str:
    if recipe.described is not None:
        return recipe.described["split"]
    r = recipe.resamples
    return f"frozen folds K={recipe.folds}, {r} resamples (seed=0..{r - 1})"
