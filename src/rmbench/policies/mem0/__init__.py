"""Mem-0: the benchmark's modular memory policy (docs/guides/train_mem0.md).

config.py      Mem0Config: every setting, with the ablation flags
memory.py      the anchor + sliding memory store and its residual cross-attention fusion
action_head.py the flow-matching transformer over action chunks
classifier.py  the subtask-end classifier's L-consecutive-steps rule
planner.py     next subtask from the first frame, the goal and the key memory
modeling.py    the executor: encoder, memory fusion, action head and end classifier
train.py       rmbench train mem0
agent.py       the closed loop behind --policy mem0:CKPT
"""
