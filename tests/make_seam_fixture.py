"""Write tests/data/online_updates.json (run once, from the code before the learner-seam refactor).

    PYTHONPATH=$PWD python tests/make_seam_fixture.py
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
