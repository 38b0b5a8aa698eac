"""depthseg edge: preprocessing, metadata, metrics, ONNX inference (torch-free), and, in
modules that import torch explicitly, the FCN-8s model, training and evaluation."""

__version__ = "0.1.0"
