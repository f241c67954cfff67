"""Learned denoisers: DnCNN with scico's pretrained weights, in numpy and on OpenCL (issue 38).

:func:`denoise` denoises a grey or colour image in [0, 1] scale at a noise level sigma with the
variant that covers it (:func:`select_variant`); :class:`DnCNN` keeps one network ready on a
backend (its weights uploaded once, its activation buffers reused between calls);
:func:`dncnn_reference` is the numpy float64/float32 reference of ``kernels/dncnn.cl``;
:func:`load_dncnn` reads the shipped weights (scico 0.0.7, BSD-3-Clause, Los Alamos National
Laboratory: ``clfza/denoisers/weights/LICENSE``). No deep-learning framework is used.

Examples
--------
>>> from clfza.denoisers import select_variant
>>> select_variant(0.1).variant
'6N'
"""

from __future__ import annotations

from ._denoise import DnCNN, DnCNNRangeWarning, VariantChoice, denoise, select_variant
from ._opencl import DnCNNDevice
from ._reference import conv3x3_circular, dncnn_reference
from ._weights import VARIANTS, DnCNNWeights, FoldedDnCNN, load_dncnn

__all__ = ["DnCNN", "DnCNNDevice", "DnCNNRangeWarning", "DnCNNWeights", "FoldedDnCNN",
           "VARIANTS", "VariantChoice", "conv3x3_circular", "denoise", "dncnn_reference",
           "load_dncnn", "select_variant"]
