"""Exports: the policy as TorchScript, ONNX and `policy.json`; the reference motion as the
dataset's CSV and as mjlab's motion file."""
