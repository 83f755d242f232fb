"""Neural pieces shared by the learned policies (Mem-0 and the baselines): the image encoder,
colour jitter, the normaliser and the text table."""
