"""The planner's upgrade path: a language model reads the key memory, LLaVA-style, and is
fine-tuned with LoRA (``pip install 'rmbench[vlm]'``: transformers and peft).

The sequence is ``[goal] <o_0> ([subtask text] <end frame>)* <query>``: each frame becomes one
token through the planner's CNN (its state MLP with observation "state") and a linear projector
into the model's embedding space, each text is tokenised. The hidden state at ``<query>`` is
scored against the candidate subtask texts and "done" by a linear head. Trained are the
encoder, the projector, the head and the LoRA adapters of the attention projections; the
language model's own weights stay frozen.

``vlm_model`` names a local Hugging Face causal-LM folder (``local_files_only``: nothing is
downloaded). Empty, it builds a tiny randomly initialised Llama with a byte-level tokeniser,
which is what the tests exercise; numbers from it mean nothing.
"""

from __future__ import annotations

import torch
from torch import nn

from rmbench.policies.mem0.inputs import observation_encoder

MAX_TEXT_TOKENS = 32


class ByteTokenizer:
    """UTF-8 bytes as token ids 0-255 (the tiny model's tokeniser; no files needed)."""

    vocab_size = 256

    def __call__(self, text: str) -> list[int]:
        return list(text.encode("utf-8"))


def _language_model(name: str):
    try:
        import transformers
    except ImportError as err:
        raise RuntimeError("planner_backend 'vlm' needs transformers and peft: "
                           "pip install 'rmbench[vlm]'") from err
    if not name:
        cfg = transformers.LlamaConfig(vocab_size=ByteTokenizer.vocab_size, hidden_size=64,
                                       intermediate_size=128, num_hidden_layers=2,
                                       num_attention_heads=4, num_key_value_heads=4,
                                       max_position_embeddings=1024)
        return transformers.LlamaForCausalLM(cfg), ByteTokenizer()
    model = transformers.AutoModelForCausalLM.from_pretrained(name, local_files_only=True)
    tok = transformers.AutoTokenizer.from_pretrained(name, local_files_only=True)
    return model, lambda text: tok(text, add_special_tokens=False)["input_ids"]


class VLMPlanner(nn.Module):
    """The planner on a language model with LoRA adapters: the same inputs and outputs as
    ``Planner`` (o_0 and the key memory in, logits over the subtask texts and "done" out)."""

    def __init__(self, cfg, texts: list[str], text_vectors=None, state_dim: int = 0):
        super().__init__()
        from peft import LoraConfig, get_peft_model

        self.use_key = cfg.use_key
        lm, tokenize = _language_model(cfg.vlm_model)
        for p in lm.parameters():
            p.requires_grad_(False)
        self.lm = get_peft_model(lm, LoraConfig(r=cfg.vlm_lora_rank, lora_alpha=2 * cfg.vlm_lora_rank,
                                                target_modules=["q_proj", "v_proj"], lora_dropout=0.0))
        hidden = lm.config.hidden_size
        self.encoders = observation_encoder(cfg, len(cfg.planner_cameras), state_dim)
        self.project = nn.Linear(cfg.dim, hidden)
        self.query = nn.Parameter(torch.randn(hidden) * 0.02)
        self.head = nn.Linear(hidden, len(texts))
        # the goal is the same for every episode of a task: a learned token, as in Planner
        self.goal = nn.Parameter(torch.randn(hidden) * 0.02)
        ids = [tokenize(t)[:MAX_TEXT_TOKENS] for t in texts]
        n = max(len(i) for i in ids)
        self.register_buffer("text_ids", torch.tensor([i + [0] * (n - len(i)) for i in ids]),
                             persistent=False)
        self.register_buffer("text_len", torch.tensor([len(i) for i in ids]), persistent=False)

    def embed(self, inputs: list[torch.Tensor]) -> torch.Tensor:
        return self.encoders(inputs).mean(1)

    def forward(self, first: torch.Tensor, keys: torch.Tensor, key_text: torch.Tensor,
                key_valid: torch.Tensor) -> torch.Tensor:
        words = self.lm.get_input_embeddings()
        rows, lengths = [], []
        for b in range(first.shape[0]):
            parts = [self.goal[None], self.project(first[b])[None]]
            if self.use_key:
                for k in torch.nonzero(key_valid[b]).flatten().tolist():
                    s = int(key_text[b, k])
                    parts.append(words(self.text_ids[s, :int(self.text_len[s])]))
                    parts.append(self.project(keys[b, k])[None])
            parts.append(self.query[None])
            row = torch.cat(parts)
            rows.append(row)
            lengths.append(len(row))
        width = max(lengths)
        # left padding: the query token sits last in every row
        seq = torch.stack([torch.cat([row.new_zeros(width - len(row), row.shape[1]), row])
                           for row in rows])
        mask = torch.stack([torch.arange(width, device=seq.device) >= width - n for n in lengths])
        out = self.lm(inputs_embeds=seq, attention_mask=mask.long(), output_hidden_states=True)
        return self.head(out.hidden_states[-1][:, -1])
