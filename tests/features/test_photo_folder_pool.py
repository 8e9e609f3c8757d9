"""The training pool reads a folder of photographs: split by photo_split, shared by FOLDER_SHARE, off by default."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from evio_lib.features.training import datasets
from evio_lib.features.training.datasets import FOLDER_SHARE, RealImages, image_pool, images_fingerprint, list_sources
from evio_lib.sim.photos import photo_split

_SIZE = (24, 32)


def _checker(level: float, shape=(60, 80)) -> np.ndarray:
    """A gray ``level`` with a +-0.1 checkerboard of 4 px squares (contrast above the pool's 0.04 floor)."""
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    return np.clip(level + 0.1 * np.where((yy // 4 + xx // 4) % 2, 1.0, -1.0), 0, 1)


@pytest.fixture(scope="module")
def photo_folder(tmp_path_factory) -> tuple[Path, dict[str, float]]:
    """A folder of PNGs, two per split plus one train-only crop, each of its own gray level; and a stray text file."""
    folder = tmp_path_factory.mktemp("photos")
    wanted = {"train": 2, "val": 2, "test": 2}
    names: list[str] = []
    for i in range(200):  # pick names until every split has two photographs (photo_split: a hash of the name)
        name = f"scene{i}/p{i}.png"
        split = photo_split(name)
        if wanted[split]:
            wanted[split] -= 1
            names.append(name)
        if not any(wanted.values()):
            break
    names.append("bsd100/crop.png")  # train only, whatever its hash
    levels = {name: 0.2 + 0.08 * k for k, name in enumerate(names)}
    for name, level in levels.items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(folder / name), np.rint(_checker(level) * 255).astype(np.uint8))
    (folder / "notes.txt").write_text("not a photograph")
    return folder, levels


def test_sources_of_each_split_are_exactly_its_photographs(photo_folder):
    folder, levels = photo_folder
    for split in ("train", "val", "test"):
        sources = [s for s in list_sources(split, photos=folder) if s.kind == "folder"]
        expected = {f"folder:{n}" for n in levels if photo_split(n) == split}
        assert {s.name for s in sources} == expected and all(s.split == split for s in sources)
        assert all(s.content == frozenset({s.name}) for s in sources)
    train = {s.name for s in list_sources("train", photos=folder)}
    assert "folder:bsd100/crop.png" in train and len([n for n in train if n.startswith("folder:")]) == 3
    assert not any(s.kind == "folder" for s in list_sources("train"))


def test_pool_holds_views_of_the_split_photographs_and_is_deterministic(photo_folder):
    folder, levels = photo_folder
    pool, names = image_pool("val", 3, _SIZE, n_images=10, photos=folder, return_sources=True)
    folder_images = [(img, n) for img, n in zip(pool, names) if n.startswith("folder:")]
    assert len(folder_images) == round(FOLDER_SHARE * 10)
    for image, name in folder_images:  # each view shows its photograph's gray level (the checkerboard averages out)
        relative = name.split(":", 1)[1]
        assert photo_split(relative) == "val"
        assert abs(float(image.mean()) - levels[relative]) < 0.04
    again = image_pool("val", 3, _SIZE, n_images=10, photos=folder)
    assert all(np.array_equal(a, b) for a, b in zip(pool, again))
    other = image_pool("val", 4, _SIZE, n_images=10, photos=folder)
    assert not all(np.array_equal(a, b) for a, b in zip(pool, other))
    data = RealImages(split="val", seed=3, size=_SIZE, n_images=10, photos=folder)
    assert all(np.array_equal(a, b) for a, b in zip(data.images, pool))


def test_pool_without_photos_is_unchanged():
    """The digest was measured on this pool before the folder kind existed (cached labels stay valid)."""
    before = "5ad5cc22d74515de913fbbbe23ad29e82e60c2d3"
    pool, names = image_pool("train", 0, n_images=8, return_sources=True, photos=None)
    assert images_fingerprint(pool) == before
    assert not any(n.startswith("folder:") for n in names)


def test_a_folder_without_photographs_of_a_split_is_refused(tmp_path):
    (tmp_path / "bsd100").mkdir()
    cv2.imwrite(str(tmp_path / "bsd100" / "a.png"), np.full((20, 20), 128, np.uint8))
    with pytest.raises(ValueError, match="holds no photographs of the val split"):
        list_sources("val", photos=tmp_path)
    with pytest.raises(ValueError, match="not a folder"):
        image_pool("train", 0, _SIZE, n_images=2, photos=tmp_path / "missing")


def test_train_config_records_the_folder_and_the_cli_refuses_a_bad_one(photo_folder, tmp_path, capsys):
    import evio_lib.features.training.train as tr

    folder, _ = photo_folder
    config = tr.load_config("detector_round1", photos=str(folder))
    assert config.photos == str(folder.resolve()) and config.to_dict()["photos"] == str(folder.resolve())
    assert tr.load_config("detector_round1").photos is None  # shipped configs: no folder
    assert tr.load_config("detector_round1", photos="none").photos is None
    assert tr.load_config("magicpoint", photos=str(folder)).photos is None  # synthetic shapes only
    fingerprint = tr.photos_fingerprint(config)
    assert fingerprint["folder"] == config.photos and fingerprint["per_split"] == {"train": 3, "val": 2, "test": 2}
    out = tmp_path / "runs"
    for bad, message in ((tmp_path / "missing", "not a folder"), (tmp_path, "holds no photographs")):
        assert tr.main_train(["detector_round1", "--photos", str(bad), "--out", str(out), "--quiet"]) == 2
        err = capsys.readouterr().err
        assert err.startswith("error: ") and message in err and err.count("\n") == 1
    assert not out.exists()  # refused before anything was written
