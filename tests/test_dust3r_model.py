"""The DUSt3R network in fingersplat3d: description parsing, state-dict layout, RoPE, heads, preprocessing."""
import math

import numpy as np
import pytest
import torch

from dust3r_tiny import tiny_model
from fingersplat3d.errors import InputError
from fingersplat3d.pointmaps.dust3r import Dust3rArchitecture, Dust3rNet, parse_model_description, prepare_image
from fingersplat3d.pointmaps.dust3r.focal import default_focal, estimate_focal
from fingersplat3d.pointmaps.dust3r.heads import LinearHead, regress_points
from fingersplat3d.pointmaps.dust3r.preprocess import crop_box, resize_weights, to_input_grid
from fingersplat3d.pointmaps.dust3r.rope import RoPE2D

# The three official checkpoints' descriptions (dust3r README, training commands).
OFFICIAL = {
    "224_linear": "AsymmetricCroCo3DStereo(pos_embed='RoPE100', img_size=(224, 224), head_type='linear', "
                  "output_mode='pts3d', depth_mode=('exp', -inf, inf), conf_mode=('exp', 1, inf), enc_embed_dim=1024, "
                  "enc_depth=24, enc_num_heads=16, dec_embed_dim=768, dec_depth=12, dec_num_heads=12)",
    "512_linear": "AsymmetricCroCo3DStereo(pos_embed='RoPE100', patch_embed_cls='ManyAR_PatchEmbed', img_size=(512, 512), "
                  "head_type='linear', output_mode='pts3d', depth_mode=('exp', -inf, inf), conf_mode=('exp', 1, inf), "
                  "enc_embed_dim=1024, enc_depth=24, enc_num_heads=16, dec_embed_dim=768, dec_depth=12, dec_num_heads=12)",
    "512_dpt": "AsymmetricCroCo3DStereo(pos_embed='RoPE100', patch_embed_cls='ManyAR_PatchEmbed', img_size=(512, 512), "
               "head_type='dpt', output_mode='pts3d', depth_mode=('exp', -inf, inf), conf_mode=('exp', 1, inf), "
               "enc_embed_dim=1024, enc_depth=24, enc_num_heads=16, dec_embed_dim=768, dec_depth=12, dec_num_heads=12)",
}


@pytest.mark.parametrize("name", sorted(OFFICIAL))
def test_official_descriptions_parse_and_round_trip(name):
    arch = parse_model_description(OFFICIAL[name])
    assert (arch.enc_embed_dim, arch.enc_depth, arch.enc_num_heads) == (1024, 24, 16)
    assert (arch.dec_embed_dim, arch.dec_depth, arch.dec_num_heads) == (768, 12, 12)
    assert arch.head_type == name.split("_")[1] and arch.img_size == (int(name[:3]),) * 2
    assert arch.depth_mode == ("exp", -math.inf, math.inf) and arch.conf_mode == ("exp", 1.0, math.inf)
    assert parse_model_description(arch.describe()) == arch


@pytest.mark.parametrize("text, message", [
    ("AsymmetricMASt3R(head_type='catmlp+dpt', output_mode='pts3d+desc24')", "unknown architecture"),
    ("__import__('os').system('touch /tmp/pwned')", "not a call expression"),
    ("AsymmetricCroCo3DStereo(enc_depth=__import__('os').getpid())", "not a literal"),
    ("AsymmetricCroCo3DStereo(pos_embed='cosine')", "pos_embed"),
    ("AsymmetricCroCo3DStereo(head_type='catmlp')", "head_type"),
    ("AsymmetricCroCo3DStereo(output_mode='pts3d+desc24')", "output_mode"),
    ("AsymmetricCroCo3DStereo(norm_layer=partial(nn.LayerNorm, eps=1e-6))", "not a literal"),
    ("AsymmetricCroCo3DStereo(enc_heads=3)", "unknown option"),
    ("AsymmetricCroCo3DStereo(head_type='dpt', dec_depth=8)", "dec_depth >= 10"),
    ("AsymmetricCroCo3DStereo(enc_embed_dim=100, enc_num_heads=3)", "heads"),
    ("AsymmetricCroCo3DStereo(img_size=(500, 512))", "multiple of patch_size"),
    ("AsymmetricCroCo3DStereo(depth_mode=('exp', 0, 10))", "depth_mode"),
    ("AsymmetricCroCo3DStereo(", "not a call expression"),
])
def test_bad_descriptions_are_clear_input_errors(text, message):
    with pytest.raises(InputError, match=message):
        parse_model_description(text)


def test_state_dict_layout_of_the_official_512_dpt_network():
    """Key names and shapes as in the official checkpoint (facts from upstream's state_dict)."""
    with torch.device("meta"):
        net = Dust3rNet(parse_model_description(OFFICIAL["512_dpt"]))
    state = net.state_dict()
    expected = {
        "mask_token": (1, 1, 768), "patch_embed.proj.weight": (1024, 3, 16, 16),
        "enc_blocks.23.attn.qkv.weight": (3072, 1024), "enc_blocks.23.mlp.fc1.weight": (4096, 1024),
        "enc_norm.weight": (1024,), "decoder_embed.weight": (768, 1024),
        "dec_blocks.11.cross_attn.projq.weight": (768, 768), "dec_blocks2.11.norm_y.bias": (768,),
        "dec_norm.weight": (768,),
        "downstream_head1.dpt.act_postprocess.0.0.weight": (96, 1024, 1, 1),
        "downstream_head1.dpt.act_postprocess.0.1.weight": (96, 96, 4, 4),
        "downstream_head2.dpt.act_postprocess.1.0.weight": (192, 768, 1, 1),
        "downstream_head2.dpt.act_postprocess.3.1.weight": (768, 768, 3, 3),
        "downstream_head1.dpt.scratch.layer1_rn.weight": (256, 96, 3, 3),
        "downstream_head1.dpt.scratch.layer_rn.3.weight": (256, 768, 3, 3),
        "downstream_head1.dpt.scratch.refinenet4.resConfUnit1.conv2.bias": (256,),
        "downstream_head2.dpt.head.4.weight": (4, 128, 1, 1),
    }
    for key, shape in expected.items():
        assert tuple(state[key].shape) == shape, key
    assert not any(key.startswith("prediction_head") or "pos_embed" in key for key in state)
    assert "enc_blocks.24.norm1.weight" not in state and "dec_blocks2.12.norm1.weight" not in state
    # Per DPT head: 16 scratch projections (8 keys, aliased), 4 x 10 fusion-block keys, 6 output, 14 reassembly.
    head_keys = [k for k in state if k.startswith("downstream_head1.")]
    assert len(head_keys) == 8 + 40 + 6 + 14
    # Parameter count of DUSt3R_ViTLarge_BaseDecoder_512_dpt (aliases counted once): ~571 M.
    assert 560e6 < sum(p.numel() for p in net.parameters()) < 580e6


def test_linear_head_keys_and_tiny_dpt_key_count_match_upstream():
    with torch.device("meta"):
        linear = Dust3rNet(parse_model_description(OFFICIAL["224_linear"]))
        tiny = Dust3rNet(Dust3rArchitecture(img_size=(512, 512), head_type="dpt", enc_embed_dim=32, enc_depth=2,
                                            enc_num_heads=2, dec_embed_dim=16, dec_depth=10, dec_num_heads=2))
    assert tuple(linear.state_dict()["downstream_head1.proj.weight"].shape) == (4 * 16 * 16, 768)
    assert len(tiny.state_dict()) == 649  # upstream's state_dict of this configuration has 649 keys


def _rotate_reference(x, position, base):
    """RoPE on one axis by explicit 2x2 rotations of pairs (k, k + D/2)."""
    dim = x.shape[-1]
    out = x.clone()
    for k in range(dim // 2):
        angle = position * base ** (-2.0 * k / dim)
        c, s = math.cos(angle), math.sin(angle)
        out[k], out[k + dim // 2] = c * x[k] - s * x[k + dim // 2], s * x[k] + c * x[k + dim // 2]
    return out


def test_rope_matches_explicit_rotations_and_sees_only_relative_positions():
    rope = RoPE2D(100.0)
    torch.manual_seed(0)
    tokens = torch.randn(1, 2, 3, 16, dtype=torch.float64)
    positions = torch.tensor([[[0, 0], [2, 5], [7, 1]]])
    rotated = rope(tokens, positions)
    for head in range(2):
        for n in range(3):
            y, x = positions[0, n].tolist()
            expected = torch.cat([_rotate_reference(tokens[0, head, n, :8], y, 100.0),
                                  _rotate_reference(tokens[0, head, n, 8:], x, 100.0)])
            assert torch.allclose(rotated[0, head, n], expected, atol=1e-6)
    q, k = torch.randn(1, 1, 2, 16, dtype=torch.float64).unbind(2)
    def score(pq, pk):
        return (rope(q[:, :, None], torch.tensor([[pq]])) * rope(k[:, :, None], torch.tensor([[pk]]))).sum()
    assert torch.allclose(score([3, 4], [1, 9]), score([13, 7], [11, 12]), atol=1e-5)


def test_linear_head_puts_each_token_patch_at_its_pixels():
    head = LinearHead(dec_embed_dim=2, patch_size=2, depth_mode=("linear", -math.inf, math.inf), conf_mode=None)
    with torch.no_grad():  # output channel c, sub-pixel (dy, dx) = token feature 0 * 100 + c * 10 + 2 * dy + dx
        head.proj.weight.zero_()
        head.proj.weight[:, 0] = 100.0
        head.proj.bias.copy_(torch.tensor([c * 10.0 + sub for c in range(3) for sub in range(4)]))
    tokens = torch.zeros(1, 6, 2)
    tokens[0, :, 0] = torch.arange(6.0)  # a 2 x 3 token grid, row-major
    points, confidence = head([tokens], (4, 6))
    assert confidence is None and points.shape == (1, 4, 6, 3)
    for row in range(4):
        for col in range(6):
            token = (row // 2) * 3 + col // 2
            sub = 2 * (row % 2) + col % 2
            assert points[0, row, col].tolist() == [100.0 * token + 10.0 * c + sub for c in range(3)]


def test_exp_depth_mode_keeps_direction_and_maps_the_norm():
    raw = torch.tensor([[3.0, 0.0, 4.0], [0.0, 0.0, 0.0]])
    points = regress_points(raw, ("exp", -math.inf, math.inf))
    assert torch.allclose(points[0], torch.tensor([0.6, 0.0, 0.8]) * math.expm1(5.0))
    assert torch.equal(points[1], torch.zeros(3))


@pytest.mark.parametrize("head_type, size", [("linear", (48, 80)), ("dpt", (48, 80))])  # 3 x 5 patches: odd grid
def test_network_outputs_match_the_input_size_and_are_batch_independent(head_type, size):
    model = tiny_model(head_type)
    torch.manual_seed(1)
    first, second = torch.rand(2, 3, *size) * 2 - 1, torch.rand(2, 3, *size) * 2 - 1
    with torch.no_grad():
        batch = model(first, second)
        single = model(first[1:], second[1:])
    assert batch.points1.shape == (2, *size, 3) and batch.confidence2.shape == (2, *size)
    assert (batch.confidence1 >= 1).all() and torch.isfinite(batch.points2).all()
    for together, alone in zip(batch, single):
        assert torch.allclose(together[1:], alone, rtol=1e-4, atol=1e-5)
    assert not torch.allclose(batch.points1[0], batch.points1[1])  # the images matter


def test_resize_weights_follow_pil():
    image_module = pytest.importorskip("PIL.Image")
    rng = np.random.default_rng(0)
    image = rng.random((37, 53)).astype(np.float32)
    for size, kernel, name in (((20, 15), image_module.LANCZOS, "lanczos"), ((90, 61), image_module.BICUBIC, "bicubic")):
        pil = np.asarray(image_module.fromarray(image, mode="F").resize(size, kernel))
        ours = resize_weights(37, size[1], name) @ image.astype(np.float64) @ resize_weights(53, size[0], name).T
        assert np.abs(pil - ours).max() < 1e-5


@pytest.mark.parametrize("original, size, resized, box", [
    ((1280, 1024), 512, (512, 410), (0, 5, 512, 405)),
    ((1024, 1280), 512, (410, 512), (5, 0, 405, 512)),
    ((600, 600), 512, (512, 512), (0, 64, 512, 448)),
    ((1280, 1024), 224, (280, 224), (28, 0, 252, 224)),
])
def test_upstream_resize_and_crop(original, size, resized, box):
    prepared = prepare_image(np.full(original[::-1], 0.25, np.float32), size)
    assert prepared.resized_size == resized and prepared.crop == box
    assert prepared.tensor.shape == (3, box[3] - box[1], box[2] - box[0])
    assert torch.allclose(prepared.tensor, torch.tensor(-0.5))  # (x - 0.5) / 0.5
    assert crop_box(resized, size, 16) == box


def test_outputs_map_back_to_each_original_pixel():
    """A map holding its own network-pixel coordinates comes back as the original pixels' coordinates."""
    prepared = prepare_image(np.zeros((90, 150), np.float32), 224)  # landscape: the square crop cuts the sides
    w, h = prepared.size
    grid = torch.stack(torch.meshgrid(torch.arange(w, dtype=torch.float64), torch.arange(h, dtype=torch.float64),
                                      indexing="xy"), dim=-1)  # [h, w, 2] = (u, v)
    values, inside = to_input_grid(grid, prepared)
    assert values.shape == (90, 150, 2) and inside.shape == (90, 150)
    v, u = np.mgrid[:90, :150]
    expected = prepared.to_network(np.stack([u, v], -1))
    interior = inside.numpy() & (expected[..., 0] >= 0) & (expected[..., 0] <= w - 1)
    assert np.abs(values.numpy()[interior] - expected[interior]).max() < 1e-4
    assert not inside[:, 0].any() and not inside[:, -1].any() and inside[:, 75].all()  # sides cut, middle kept
    assert 0.55 < inside.numpy().mean() < 0.65  # 90 of 150 columns


def test_focal_of_a_pinhole_pointmap_is_recovered():
    height, width, focal = 40, 60, 137.0
    v, u = np.mgrid[:height, :width]
    depth = 5.0 + 0.3 * np.sin(u / 7.0)
    points = np.stack([(u - (width - 1) / 2) / focal * depth, (v - (height - 1) / 2) / focal * depth, depth], -1)
    valid = torch.ones(height, width, dtype=torch.bool)
    assert abs(estimate_focal(torch.tensor(points), valid) - focal) < 1e-6
    assert estimate_focal(torch.tensor(-points), valid) == default_focal(width, height)  # all behind: fallback
