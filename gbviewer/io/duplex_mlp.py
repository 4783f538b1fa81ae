"""The MLPs of a Duplex-GS checkpoint (docs/formats.md#duplex-gs), loaded with PyTorch: TorchScript files beside the
anchor ply (or in a `checkpoint.pth/` folder there), or the state dicts of one `checkpoints.pth` ('unite' mode) rebuilt
as the published Linear-ReLU-Linear(-activation) stacks. torch is imported only here (`pip install
'gbviewer[duplex]'`); a missing torch is the checkpoint's SceneFormatError."""

from __future__ import annotations

import warnings
from pathlib import Path

from ..core.errors import SceneFormatError

MLP_FILES = {"opacity": "opacity_mlp.pt", "cov": "cov_mlp.pt", "color": "color_mlp.pt"}
OPTIONAL_FILES = {"feature_bank": "feature_bank_mlp.pt", "appearance": "embedding_appearance.pt"}
UNITE_FILE = "checkpoints.pth"


def import_torch(path: Path):
    try:
        import torch
    except ImportError as exc:
        raise SceneFormatError(
            path,
            f"a Duplex-GS checkpoint needs PyTorch to run its MLPs ({exc}); install it with "
            "pip install 'gbviewer[duplex]'",
        ) from None
    return torch


def linear_shapes(module) -> list[tuple[int, int]]:
    """(in, out) of every weight matrix of a (scripted) module, in order."""
    return [
        (int(p.shape[1]), int(p.shape[0]))
        for name, p in module.named_parameters()
        if name.endswith("weight") and p.dim() == 2
    ]


def _rebuild(torch, state: dict, kind: str):
    """A published MLP from its state dict ('unite' checkpoints): Linear-ReLU-Linear + the kind's activation."""
    nn = torch.nn
    if kind == "appearance":
        w = state["embedding.weight"] if "embedding.weight" in state else state["weight"]
        emb = nn.Embedding(w.shape[0], w.shape[1])
        emb.weight.data.copy_(w)
        return emb
    w0, w2 = state["0.weight"], state["2.weight"]
    layers = [nn.Linear(w0.shape[1], w0.shape[0]), nn.ReLU(True), nn.Linear(w2.shape[1], w2.shape[0])]
    act = {"opacity": nn.Tanh(), "color": nn.Sigmoid(), "feature_bank": nn.Softmax(dim=1)}.get(kind)
    seq = nn.Sequential(*layers, *([act] if act is not None else []))
    seq.load_state_dict({k: v for k, v in state.items() if k.split(".")[0] in ("0", "2")})
    return seq.eval()


def load_mlps(path: Path, torch) -> dict:
    """The checkpoint's MLPs (TorchScript files or a 'unite' checkpoints.pth) found beside the ply."""
    folders = [path.parent, path.parent / "checkpoint.pth"]
    for folder in folders:
        if all((folder / f).is_file() for f in MLP_FILES.values()):
            mlps = {}
            for kind, fname in {**MLP_FILES, **OPTIONAL_FILES}.items():
                f = folder / fname
                if kind in OPTIONAL_FILES and not f.is_file():
                    continue
                try:
                    with warnings.catch_warnings():  # torch 2.x deprecates TorchScript, which these files are
                        warnings.simplefilter("ignore", DeprecationWarning)
                        mlps[kind] = torch.jit.load(str(f), map_location="cpu").eval()
                except Exception as exc:  # noqa: BLE001 - torch raises RuntimeError / ValueError with its message
                    raise SceneFormatError(f, f"not a TorchScript module: {str(exc).splitlines()[0]}") from None
            return mlps
    unite = path.parent / UNITE_FILE
    if unite.is_file():
        try:
            ckpt = torch.load(str(unite), map_location="cpu", weights_only=True)
        except Exception as exc:  # noqa: BLE001
            raise SceneFormatError(unite, f"cannot read the MLP checkpoint: {str(exc).splitlines()[0]}") from None
        keys = {
            "opacity": "opacity_mlp",
            "cov": "cov_mlp",
            "color": "color_mlp",
            "feature_bank": "feature_bank_mlp",
            "appearance": "appearance",
        }
        missing = [k for k in ("opacity_mlp", "cov_mlp", "color_mlp") if k not in ckpt]
        if missing:
            raise SceneFormatError(unite, f"missing state dicts {missing}")
        try:
            return {kind: _rebuild(torch, ckpt[key], kind) for kind, key in keys.items() if key in ckpt}
        except (KeyError, RuntimeError) as exc:
            raise SceneFormatError(unite, f"unexpected MLP state dict: {exc}") from None
    present = [f for f in MLP_FILES.values() if (path.parent / f).is_file()]
    missing = [f for f in MLP_FILES.values() if f not in present]
    raise SceneFormatError(
        path.parent / missing[0],
        "missing: a Duplex-GS checkpoint needs "
        f"{', '.join(MLP_FILES.values())} (or {UNITE_FILE}) beside {path.name}; found "
        f"{present or 'none of them'}",
    )
