"""Dataset listings for dataset runs: layouts, --select, CSV lists, missing frames, all without reading pixels."""
from __future__ import annotations

import numpy as np
import pytest

from fingersplat3d.errors import InputError
from fingersplat3d.io.images import write_image
from fingersplat3d.io.jobs import list_jobs, load_job, parse_select


def uwa_folder(tmp_path, frames=(0, 1, 2)):
    folder = tmp_path / "uwa"
    folder.mkdir()
    image = np.full((8, 10), 0.5, np.float32)
    for stem in ("1_1_1_1", "1_2_1_1", "2_1_3_1"):
        for frame in frames if stem != "2_1_3_1" else frames[:2]:
            write_image(folder / f"{stem}_{frame}.png", image)
    return folder


def test_uwa_jobs_select_and_missing_frames(tmp_path):
    folder = uwa_folder(tmp_path)
    jobs = list_jobs([folder])
    assert [job.name for job in jobs] == ["1_1_1_1", "1_2_1_1", "2_1_3_1"]
    assert jobs[0].ids == {"subject": "1", "finger": "1", "capture": "1"} and len(jobs[0].files) == 3
    assert jobs[2].problem and "missing frame" in jobs[2].problem
    with pytest.raises(InputError, match="missing frame"):
        load_job(jobs[2])
    assert list(load_job(jobs[0]).names) == ["f0", "f1", "f2"] and load_job(jobs[0]).metadata["name"] == "1_1_1_1"
    assert [job.name for job in list_jobs([folder], "finger=2")] == ["1_2_1_1"]
    assert [job.name for job in list_jobs([folder], "subject=1,subject=2,count=2")] == ["1_1_1_1", "1_2_1_1"]
    assert [job.name for job in list_jobs([folder], "name=2_1_3_1")] == ["2_1_3_1"]
    with pytest.raises(InputError, match="no capture matches"):
        list_jobs([folder], "subject=9")


def test_a_folder_without_images_or_captures_is_refused_at_listing(tmp_path):
    empty = tmp_path / "empty"
    (empty / "notes").mkdir(parents=True)
    (empty / "notes" / "readme.txt").write_text("no photos here")
    with pytest.raises(InputError, match="holds no images and no capture folders"):
        list_jobs([empty])


def test_a_folder_of_photo_folders_is_one_capture_each(tmp_path, capsys):
    """One folder per capture, each with its photos (no dataset naming): a job each, named after it; photos of the
    folder's own make it one capture, as before; a fuse pointed at the folder above names the folders that hold
    photos."""
    from fingersplat3d.cli import main

    root = tmp_path / "mine"
    image = np.full((8, 10), 0.5, np.float32)
    for capture in ("finger 10", "finger 2"):
        for view in ("left", "front", "right"):
            write_image(root / capture / f"{view}.png", image)
    (root / ".hidden").mkdir()
    write_image(root / ".hidden" / "x.png", image)
    (root / "notes").mkdir()
    (root / "notes" / "readme.txt").write_text("no photos")
    jobs = list_jobs([root])
    assert [job.name for job in jobs] == ["finger 2", "finger 10"] and all(len(load_job(job)) == 3 for job in jobs)
    write_image(root / "extra.png", image)  # a photo of its own: the folder is one capture of its photos
    assert [job.name for job in list_jobs([root])] == ["mine"]
    (root / "extra.png").unlink()
    capsys.readouterr()
    assert main(["fuse", str(root), "-o", str(tmp_path / "out"), "--no-splat"]) == 2
    said = capsys.readouterr().err
    assert "holds no images" in said and "folders 'finger 10', 'finger 2' hold photos" in said and "fs3d batch" in said
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("text", ["count=0", "colour=red", "subject", "count=x"])
def test_bad_select_is_one_sentence(text):
    with pytest.raises(InputError, match="--select"):
        parse_select(text)


def test_csv_lists_and_capture_folders(tmp_path, uwa640):
    from fingersplat3d.io.capture import write_capture

    root = tmp_path / "captures"
    write_capture(uwa640, root / "a")
    write_capture(uwa640, root / "b")
    assert [job.name for job in list_jobs([root])] == ["a", "b"]
    listing = tmp_path / "list.csv"
    listing.write_text("name,paths\nfirst,captures/a\nsecond,captures/b/images/left.png;captures/b/images/center.png\n")
    jobs = list_jobs([listing])
    assert [job.name for job in jobs] == ["first", "second"] and len(jobs[1].files) == 2
    assert len(load_job(jobs[1])) == 2 and len(load_job(jobs[0])) == 3
    listing.write_text("name,paths\nfirst,a\nfirst,b\n")
    with pytest.raises(InputError, match="twice"):
        list_jobs([listing])
    listing.write_text("file\nx\n")
    with pytest.raises(InputError, match="name,paths"):
        list_jobs([listing])
    with pytest.raises(InputError, match="not found"):
        list_jobs([tmp_path / "nowhere"])
