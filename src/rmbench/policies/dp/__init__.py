"""Diffusion Policy (Chi et al. 2023), the CNN variant, as a memoryless baseline."""
