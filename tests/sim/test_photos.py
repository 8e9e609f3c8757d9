"""The photo folder: split by name (stable, Berkeley crops train only), listing, decoding and the --photos option."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from evio_lib.events.reconstruction.training_set import (TrainingSetConfig, load_sequence, make_sequence,
                                                         make_training_set)
from evio_lib.sim import photos as photo_module
from evio_lib.sim.photos import (list_photos, load_photo, photo_fingerprint, photo_split, resolve_photo_option)


def _write_folder(folder, names, seed=0):
    rng = np.random.default_rng(seed)
    for name in names:
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        image = cv2.GaussianBlur(rng.uniform(0, 255, (60, 80)).astype(np.float32), (0, 0), 2.0)
        assert cv2.imwrite(str(path), np.clip(image, 0, 255).astype(np.uint8))
    return folder


def test_the_split_depends_on_the_name_alone_and_berkeley_crops_only_train():
    names = [f"urban100/img_{i:03d}.png" for i in range(400)]
    splits = [photo_split(n) for n in names]
    shares = {s: splits.count(s) / len(splits) for s in ("train", "val", "test")}
    assert 0.13 < shares["val"] < 0.27 and 0.13 < shares["test"] < 0.27, shares   # 20 % each by the hash
    assert {photo_split(f"bsd_train400/test_{i:03d}.png") for i in range(200)} == {"train"}
    assert {photo_split(f"bsd100/{i}.png") for i in range(200)} == {"train"}
    # the split is the hash rule itself: a name whose first 8 hex digits of sha256 give u < 0.2 is validation
    import hashlib

    u = int(hashlib.sha256(b"urban100/img_000.png").hexdigest()[:8], 16) / 2 ** 32
    assert photo_split("urban100/img_000.png") == ("val" if u < 0.2 else "test" if u < 0.4 else "train")


def test_listing_loading_and_the_fingerprint(tmp_path):
    names = [f"urban100/img_{i:03d}.png" for i in range(30)] + ["bsd100/x.jpg", "notes.txt"]
    folder = _write_folder(tmp_path / "photos", [n for n in names if n.endswith((".png", ".jpg"))])
    (folder / "notes.txt").write_text("not a photo")
    every = list_photos(folder)
    assert len(every) == 31 and all(p.suffix in (".png", ".jpg") for p in every)
    by_split = {s: list_photos(folder, s) for s in ("train", "val", "test")}
    assert sum(map(len, by_split.values())) == 31
    assert not set(by_split["val"]) & set(by_split["train"])
    fingerprint = photo_fingerprint(folder)
    assert fingerprint["count"] == 31 and fingerprint["per_split"]["val"] == len(by_split["val"])
    image = load_photo(every[0])
    assert image.dtype == np.float32 and image.shape == (60, 80) and 0 <= image.min() < image.max() <= 1
    deep = np.full((20, 20), 65535, np.uint16)
    cv2.imwrite(str(tmp_path / "deep.png"), deep)
    assert load_photo(tmp_path / "deep.png").max() == 1.0                  # 16-bit scaled by 65535
    (tmp_path / "broken.png").write_bytes(b"not a png")
    with pytest.raises(ValueError, match="broken.png: not a readable photograph"):
        load_photo(tmp_path / "broken.png")


def test_the_option_and_its_refusals(tmp_path, monkeypatch):
    with pytest.raises(ValueError, match="--photos .*missing: not a folder"):
        list_photos(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="holds no photographs"):
        resolve_photo_option(tmp_path / "empty")
    assert resolve_photo_option("none") is None
    monkeypatch.setenv("EVIO_PHOTOS", str(tmp_path / "mine"))
    with pytest.raises(ValueError, match=r"^\$EVIO_PHOTOS=.*mine: not a folder"):
        resolve_photo_option("auto")
    (tmp_path / "mine").mkdir()
    assert resolve_photo_option("auto") == tmp_path / "mine" == photo_module.default_photo_folder()


SMALL = TrainingSetConfig(height=32, width=32, windows=4, duration_min=0.3, duration_max=0.4)


def test_sequences_on_photographs_are_deterministic_and_use_them(tmp_path):
    folder = _write_folder(tmp_path / "photos", [f"p/img_{i}.png" for i in range(6)])
    photos = tuple(str(p) for p in list_photos(folder))
    a, _ = make_sequence(np.random.default_rng(3), "train", SMALL, photos=photos)
    b, _ = make_sequence(np.random.default_rng(3), "train", SMALL, photos=photos)
    c, _ = make_sequence(np.random.default_rng(3), "train", SMALL)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    assert not np.array_equal(a["frames"], c["frames"])                    # the photographs changed the scene


def test_a_set_records_its_photographs_and_refuses_others(tmp_path):
    names = [f"urban100/img_{i:03d}.png" for i in range(40)]
    folder = _write_folder(tmp_path / "photos", names)
    make_training_set(tmp_path / "set", sequences=2, val=1, test=1, seed=0, config=SMALL, workers=1, progress=False,
                      photos=folder)
    manifest = json.loads((tmp_path / "set" / "training_set.json").read_text())
    assert manifest["photos"] == photo_fingerprint(folder) and manifest["complete"]
    assert load_sequence(tmp_path / "set" / "train" / "seq_00001.npz")["frames"].shape == (4, 32, 32)
    other = _write_folder(tmp_path / "other", names[:-1])
    with pytest.raises(ValueError, match="other settings"):
        make_training_set(tmp_path / "set", sequences=2, val=1, test=1, seed=0, config=SMALL, workers=1,
                          progress=False, photos=other)
    make_training_set(tmp_path / "plain", sequences=1, val=1, test=0, seed=0, config=SMALL, workers=1,
                      progress=False)
    assert "photos" not in json.loads((tmp_path / "plain" / "training_set.json").read_text())
    with pytest.raises(ValueError, match="made without photographs; to resume or extend it, give --photos none"):
        make_training_set(tmp_path / "plain", sequences=2, val=1, test=0, seed=0, config=SMALL, workers=1,
                          progress=False, photos=folder)
