"""Training shared by the learned policies: one loop (optimiser, schedule, checkpoints,
resume, loss curves, DDP) and the batch sources it draws from."""
