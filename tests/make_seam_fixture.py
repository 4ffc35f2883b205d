"""Write tests/data/online_updates.json: a few fixed-seed online updates of each agent (see seam_reference.py).

    ATEN_CPU_CAPABILITY=avx2 ONEDNN_MAX_CPU_ISA=AVX2 PYTHONPATH=$PWD python tests/make_seam_fixture.py

The record names the torch version and CPU kernels that wrote it. The packaged one was written with the AVX2
kernels forced (as above), which reproduce bit for bit the record the code before the learner seam wrote on an
AVX2 machine (its sha256 digests of every tensor matched); test_seam.py compares any machine with it up to
seam_reference.RTOL.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

from seam_reference import record_all  # noqa: E402

if __name__ == "__main__":
    target = Path(__file__).parent / "data" / "online_updates.json"
    target.write_text(json.dumps(record_all(), indent=1, sort_keys=True) + "\n")
    print(f"wrote {target}")
