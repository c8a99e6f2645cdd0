"""Our PyTorch RAFT (Teed & Deng, ECCV 2020), one file per component as in the paper's ``core/``:

- :mod:`.extractor`  feature and context encoders (residual / bottleneck blocks)
- :mod:`.corr`       all-pairs correlation pyramid, :class:`CorrBlock`
- :mod:`.update`     motion encoder, ConvGRU / SepConvGRU, flow head, upsampling-mask head
- :mod:`.upsample`   convex (learned) and bilinear ×8 upsampling
- :mod:`.padder`     :class:`InputPadder` (pad to multiples of 8 and back)
- :mod:`.model`      :class:`RAFT`, the iterative loop
- :mod:`.weights`    checkpoint loading: official, torchvision and flowgap layouts, cached per process
- :mod:`.backend`    :class:`RaftBackend`, the ``FlowBackend`` named "raft"

Importing this package imports torch.
"""

from companion.flow.raft.model import RAFT, RaftConfig, RaftOutput
from companion.flow.raft.padder import InputPadder

__all__ = ["RAFT", "InputPadder", "RaftConfig", "RaftOutput"]
