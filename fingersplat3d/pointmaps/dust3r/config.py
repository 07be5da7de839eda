"""The model description of a DUSt3R checkpoint, parsed safely.

Official checkpoints describe their network with a Python call expression in ``args.model``::

    AsymmetricCroCo3DStereo(pos_embed='RoPE100', patch_embed_cls='ManyAR_PatchEmbed', img_size=(512, 512),
        head_type='dpt', output_mode='pts3d', depth_mode=('exp', -inf, inf), conf_mode=('exp', 1, inf),
        enc_embed_dim=1024, enc_depth=24, enc_num_heads=16, dec_embed_dim=768, dec_depth=12, dec_num_heads=12)

Upstream ``eval()``s that string; here it is parsed with :mod:`ast` and only literals (numbers,
strings, tuples, ``inf``) are accepted. Another class name, an option this implementation does not
have, or a value it does not support is an :class:`~fingersplat3d.errors.InputError`.
Unset options take upstream's defaults (CroCoNet's and AsymmetricCroCo3DStereo's).
"""
from __future__ import annotations

import ast
import math
from dataclasses import dataclass

from ...errors import InputError

__all__ = ["Dust3rArchitecture", "parse_model_description", "ARCHITECTURE_CLASS"]

ARCHITECTURE_CLASS = "AsymmetricCroCo3DStereo"
_IGNORED = {"freeze", "landscape_only", "mask_ratio"}  # training-only switches (upstream forces landscape_only=False at load)
_PATCH_EMBEDS = {"PatchEmbedDust3R", "ManyAR_PatchEmbed"}  # same weights; upstream loads both as PatchEmbedDust3R


@dataclass(frozen=True)
class Dust3rArchitecture:
    """The hyper-parameters that shape the network (and its state dict)."""

    img_size: tuple[int, int] = (224, 224)
    """Training resolution (H, W); 224 selects square-crop preprocessing, anything else long-side resizing."""
    patch_size: int = 16
    """Side of the square patches of the encoder."""
    enc_embed_dim: int = 768
    """Encoder token width."""
    enc_depth: int = 12
    """Number of encoder blocks."""
    enc_num_heads: int = 12
    """Attention heads per encoder block."""
    dec_embed_dim: int = 512
    """Decoder token width."""
    dec_depth: int = 8
    """Number of decoder blocks (per view)."""
    dec_num_heads: int = 16
    """Attention heads per decoder block."""
    mlp_ratio: float = 4.0
    """MLP hidden width over token width."""
    norm_im2_in_dec: bool = True
    """LayerNorm the other view's tokens before cross-attention."""
    rope_base: float = 100.0
    """Frequency base of the 2D rotary embedding (``pos_embed='RoPE100'``)."""
    head_type: str = "linear"
    """``linear`` (one linear map per patch) or ``dpt`` (multi-scale convolutional head)."""
    depth_mode: tuple[str, float, float] = ("exp", -math.inf, math.inf)
    """How the head's raw xyz becomes a point: ``exp`` (norm through expm1), ``square`` or ``linear``."""
    conf_mode: tuple[str, float, float] | None = ("exp", 1.0, math.inf)
    """How the raw 4th channel becomes a confidence (``exp``: ``vmin + exp(x)``), or None: no confidence."""
    patch_embed_cls: str = "PatchEmbedDust3R"
    """Upstream's patch-embedding class name (only kept to write the description back)."""

    def __post_init__(self) -> None:
        problems = []
        positive = ("patch_size", "enc_embed_dim", "enc_depth", "enc_num_heads", "dec_embed_dim", "dec_depth",
                    "dec_num_heads")
        for name in positive:
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                problems.append(f"{name} must be a positive integer, got {value!r}")
        if not problems:
            for width, heads, part in ((self.enc_embed_dim, self.enc_num_heads, "encoder"),
                                       (self.dec_embed_dim, self.dec_num_heads, "decoder")):
                if width % heads or (width // heads) % 4:
                    problems.append(f"the {part} width {width} must split into heads of a multiple of 4 features "
                                    f"({heads} heads)")
            if any(not isinstance(s, int) or s % self.patch_size for s in self.img_size):
                problems.append(f"img_size {self.img_size} must be a multiple of patch_size {self.patch_size}")
        if self.head_type not in ("linear", "dpt"):
            problems.append(f"head_type {self.head_type!r} is not supported (linear, dpt)")
        elif self.head_type == "dpt" and isinstance(self.dec_depth, int) and self.dec_depth < 10:
            problems.append(f"the dpt head needs dec_depth >= 10, got {self.dec_depth}")
        if not (isinstance(self.mlp_ratio, (int, float)) and self.mlp_ratio > 0):
            problems.append(f"mlp_ratio must be positive, got {self.mlp_ratio!r}")
        if not (self.rope_base > 0):
            problems.append(f"the RoPE base must be positive, got {self.rope_base!r}")
        if not (isinstance(self.depth_mode, tuple) and len(self.depth_mode) == 3
                and self.depth_mode[0] in ("exp", "square", "linear")
                and self.depth_mode[1] == -math.inf and self.depth_mode[2] == math.inf):
            problems.append(f"depth_mode {self.depth_mode!r} is not supported (exp, square or linear, unbounded)")
        if self.conf_mode is not None and not (isinstance(self.conf_mode, tuple) and len(self.conf_mode) == 3
                                               and self.conf_mode[0] in ("exp", "sigmoid")):
            problems.append(f"conf_mode {self.conf_mode!r} is not supported (exp or sigmoid)")
        if self.patch_embed_cls not in _PATCH_EMBEDS:
            problems.append(f"patch_embed_cls {self.patch_embed_cls!r} is not supported")
        if problems:
            raise InputError("unsupported DUSt3R architecture: " + "; ".join(problems))

    def describe(self) -> str:
        """The ``args.model`` string of this architecture, in upstream's syntax (upstream can eval it)."""
        def literal(value) -> str:
            if isinstance(value, float) and math.isinf(value):
                return "inf" if value > 0 else "-inf"
            if isinstance(value, float) and value.is_integer():
                return str(int(value))
            if isinstance(value, tuple):
                return "(" + ", ".join(literal(v) for v in value) + ")"
            return repr(value)

        fields = [("pos_embed", f"RoPE{self.rope_base:g}"), ("patch_embed_cls", self.patch_embed_cls),
                  ("img_size", self.img_size), ("head_type", self.head_type), ("output_mode", "pts3d"),
                  ("depth_mode", self.depth_mode), ("conf_mode", self.conf_mode),
                  ("enc_embed_dim", self.enc_embed_dim), ("enc_depth", self.enc_depth),
                  ("enc_num_heads", self.enc_num_heads), ("dec_embed_dim", self.dec_embed_dim),
                  ("dec_depth", self.dec_depth), ("dec_num_heads", self.dec_num_heads),
                  ("patch_size", self.patch_size), ("mlp_ratio", float(self.mlp_ratio)),
                  ("norm_im2_in_dec", self.norm_im2_in_dec)]
        return f"{ARCHITECTURE_CLASS}(" + ", ".join(f"{k}={literal(v)}" for k, v in fields) + ")"


def _literal(node: ast.AST):
    """Evaluate a literal: numbers, strings, booleans, None, tuples/lists, ``inf`` and ``-x``."""
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float, str, bool, type(None))):
        return node.value
    if isinstance(node, (ast.Tuple, ast.List)):
        return tuple(_literal(element) for element in node.elts)
    if isinstance(node, ast.Name) and node.id == "inf":
        return math.inf
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        value = _literal(node.operand)
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return -value if isinstance(node.op, ast.USub) else value
    if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "float"
            and len(node.args) == 1 and not node.keywords and isinstance(node.args[0], ast.Constant)
            and node.args[0].value in ("inf", "-inf", "+inf")):
        return float(node.args[0].value)
    raise ValueError(f"not a literal: {ast.unparse(node)[:60]}")


def _pair(value, name: str) -> tuple[int, int]:
    if isinstance(value, int) and not isinstance(value, bool):
        return (value, value)
    if isinstance(value, tuple) and len(value) == 2 and all(isinstance(v, int) and not isinstance(v, bool) for v in value):
        return value
    raise InputError(f"unsupported DUSt3R architecture: {name} must be an integer or a pair, got {value!r}")


def _mode(value, name: str):
    if value is None and name == "conf_mode":
        return None
    if not (isinstance(value, tuple) and len(value) == 3 and isinstance(value[0], str)
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value[1:])):
        raise InputError(f"unsupported DUSt3R architecture: {name} must be (mode, min, max), got {value!r}")
    return (value[0], float(value[1]), float(value[2]))


def parse_model_description(text: str) -> Dust3rArchitecture:
    """Parse ``args.model`` (see the module docstring); never evaluates code."""
    if not isinstance(text, str) or not text.strip():
        raise InputError("the checkpoint has no model description string")
    try:
        tree = ast.parse(text.strip(), mode="eval").body
    except SyntaxError:
        raise InputError(f"the model description is not a call expression: {text[:80]!r}") from None
    if not isinstance(tree, ast.Call) or not isinstance(tree.func, ast.Name):
        raise InputError(f"the model description is not a call expression: {text[:80]!r}")
    if tree.func.id != ARCHITECTURE_CLASS:
        raise InputError(f"unknown architecture {tree.func.id!r}: only {ARCHITECTURE_CLASS} (DUSt3R) is supported")
    if tree.args or any(keyword.arg is None for keyword in tree.keywords):
        raise InputError(f"unsupported model description: only keyword arguments are understood in {text[:80]!r}")
    options = {}
    for keyword in tree.keywords:
        try:
            options[keyword.arg] = _literal(keyword.value)
        except ValueError as error:
            raise InputError(f"unsupported DUSt3R architecture: option {keyword.arg}: {error}") from None
    values = {}
    for name, value in options.items():
        if name in _IGNORED:
            continue
        if name == "output_mode":
            if value != "pts3d":
                raise InputError(f"unsupported DUSt3R architecture: output_mode {value!r} (only 'pts3d')")
        elif name == "pos_embed":
            if not (isinstance(value, str) and value.startswith("RoPE")):
                raise InputError(f"unsupported DUSt3R architecture: pos_embed {value!r} (only RoPE<base>)")
            try:
                values["rope_base"] = float(value[len("RoPE"):])
            except ValueError:
                raise InputError(f"unsupported DUSt3R architecture: pos_embed {value!r}") from None
        elif name == "img_size":
            values["img_size"] = _pair(value, name)
        elif name in ("depth_mode", "conf_mode"):
            values[name] = _mode(value, name)
        elif name in ("patch_size", "enc_embed_dim", "enc_depth", "enc_num_heads", "dec_embed_dim", "dec_depth",
                      "dec_num_heads", "mlp_ratio", "norm_im2_in_dec", "head_type", "patch_embed_cls"):
            if name == "patch_size":
                side, other = _pair(value, name)
                if side != other:
                    raise InputError(f"unsupported DUSt3R architecture: non-square patches {value!r}")
                value = side
            values[name] = value
        else:
            raise InputError(f"unsupported DUSt3R architecture: unknown option {name!r}")
    return Dust3rArchitecture(**values)
