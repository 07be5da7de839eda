"""DUSt3R checkpoints: the official layout round-trips through the real loading code; bad files are clear errors."""
import argparse
import zipfile
from pathlib import Path

import pytest
import torch

from dust3r_tiny import tiny_checkpoint, tiny_model
from fingersplat3d.errors import InputError
from fingersplat3d.pointmaps.dust3r import load_model, read_checkpoint


@pytest.mark.parametrize("head_type", ["linear", pytest.param("dpt", marks=pytest.mark.slow)])  # dpt: a 150 MB file
def test_official_layout_round_trip_is_strict_and_exact(tmp_path, head_type):
    model = tiny_model(head_type, seed=3)
    path = tiny_checkpoint(tmp_path, head_type, seed=3)
    content = torch.load(path, weights_only=False)  # what the file holds (our own file: trusted here)
    assert set(content) == {"model", "args"} and isinstance(content["args"], argparse.Namespace)
    assert content["args"].model.startswith("AsymmetricCroCo3DStereo(") and f"head_type='{head_type}'" in content["args"].model
    loaded = load_model(path)
    assert loaded.architecture == model.architecture and not loaded.training
    for key, value in model.state_dict().items():
        assert torch.equal(loaded.state_dict()[key], value), key
    images = torch.rand(1, 3, 32, 48) * 2 - 1
    with torch.no_grad():
        for ours, theirs in zip(loaded(images, images.flip(3)), model(images, images.flip(3))):
            assert torch.equal(ours, theirs)


def _save(path: Path, state: dict, args) -> Path:
    torch.save({"model": state, "args": args}, path)
    return path


def test_args_may_be_a_dict_or_a_string_and_extra_entries_are_ignored(tmp_path):
    model = tiny_model()
    description = model.architecture.describe()
    for args in ({"model": description}, description):
        path = tmp_path / f"{type(args).__name__}.pth"
        torch.save({"model": model.state_dict(), "args": args, "epoch": 7, "best_so_far": 0.5}, path)
        assert read_checkpoint(path).architecture == model.architecture


def test_missing_decoder2_takes_decoder1_weights_as_upstream(tmp_path):
    model = tiny_model()
    state = {k: v for k, v in model.state_dict().items() if not k.startswith("dec_blocks2.")}
    loaded = load_model(_save(tmp_path / "croco_init.pth", state, argparse.Namespace(model=model.architecture.describe())))
    assert torch.equal(loaded.dec_blocks2[1].mlp.fc2.weight, model.dec_blocks[1].mlp.fc2.weight)


def test_missing_file_is_a_clear_error(tmp_path):
    with pytest.raises(InputError, match=r"nope\.pth: checkpoint file not found"):
        load_model(tmp_path / "nope.pth")
    with pytest.raises(InputError, match="is not a file"):
        load_model(tmp_path)


def test_corrupt_files_are_clear_errors(tmp_path):
    garbage = tmp_path / "garbage.pth"
    garbage.write_bytes(b"not a checkpoint at all" * 50)
    truncated = tmp_path / "truncated.pth"
    truncated.write_bytes(tiny_checkpoint(tmp_path).read_bytes()[:5000])
    empty = tmp_path / "empty.pth"
    empty.write_bytes(b"")
    for path in (garbage, truncated, empty):
        with pytest.raises(InputError, match=rf"{path.name}: is corrupt or not a PyTorch checkpoint"):
            load_model(path)
    assert zipfile.is_zipfile(tiny_checkpoint(tmp_path))  # the good file is the zip format torch writes


class _Trap:
    """Unpickling this would create a marker file (it must never run)."""

    marker = None

    def __reduce__(self):
        return (Path.touch, (self.marker,))


def test_objects_other_than_weights_are_never_unpickled(tmp_path):
    marker = tmp_path / "code_ran"
    trap = _Trap()
    trap.marker = marker
    path = tmp_path / "trap.pth"
    torch.save({"model": tiny_model().state_dict(), "args": trap}, path)
    with pytest.raises(InputError, match="trap.pth: holds Python objects other than weights"):
        load_model(path)
    assert not marker.exists()


def test_unknown_or_mismatched_architectures_are_clear_errors(tmp_path):
    model = tiny_model()
    state = model.state_dict()
    description = model.architecture.describe()
    cases = {
        "mast3r.pth": (state, argparse.Namespace(model="AsymmetricMASt3R(pos_embed='RoPE100', head_type='catmlp+dpt')"),
                       "mast3r.pth: unknown architecture 'AsymmetricMASt3R'"),
        "no_args.pth": (state, None, "no_args.pth: the checkpoint has no model description"),
        "missing_key.pth": ({k: v for k, v in state.items() if k != "enc_norm.weight"}, argparse.Namespace(model=description),
                            r"missing_key.pth: the weights do not match .* 1 missing \(enc_norm.weight\)"),
        "extra_key.pth": ({**state, "prediction_head.weight": torch.zeros(3)}, argparse.Namespace(model=description),
                          r"1 unexpected \(prediction_head.weight\)"),
        "wrong_shape.pth": (dict(state, **{"decoder_embed.weight": torch.zeros(16, 64)}),
                            argparse.Namespace(model=description), r"wrong shape \(decoder_embed.weight \(16, 64\) vs \(16, 32\)\)"),
        "deeper.pth": (state, argparse.Namespace(model=description.replace("enc_depth=2", "enc_depth=3")),
                       r"12 missing \(enc_blocks.2"),
        "nan.pth": (dict(state, **{"enc_norm.bias": torch.full((32,), float("nan"))}), argparse.Namespace(model=description),
                    "nan.pth: the weights contain NaN"),
    }
    for name, (weights, args, message) in cases.items():
        with pytest.raises(InputError, match=message):
            load_model(_save(tmp_path / name, weights, args))
    not_a_dict = tmp_path / "list.pth"
    torch.save([1, 2, 3], not_a_dict)
    with pytest.raises(InputError, match="list.pth: is not a DUSt3R checkpoint"):
        load_model(not_a_dict)
