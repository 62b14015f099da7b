"""The adversarial corpus: stages a new or a hostile user feeds wsoft, and what each must give.

Every case writes a small stage (or a broken file) into a folder and says what is expected of
every technique that supports it: ``ok`` (exit 0, no NaN, and where the answer is known, the
answer: full shadow under a lamp shade, the occluder's shadow unchanged by a far huge triangle)
or ``error`` (exit 2, one line naming the file and the prim, no traceback). Warnings a case must
raise are listed too. :func:`judge` tells what is wrong with a result; the expectations hold at
the frame size and settings below.

The sweep ``wsoft bench adversarial`` (``wsoft.bench.adversarial``) runs every case through the
command line in-process, exactly as a user runs them (``wsoft render STAGE -t TECH --out ...
--stats ...``), and ``tests/test_adversarial.py`` runs it on CPU in CI.
"""

from wsoft.stages.adversarial.cases import BASES, CASES, KNOWN, judge, write_stage
from wsoft.stages.adversarial.checks import all_dark, all_lit, close_to, far_side_dark, same_as, same_as_base
from wsoft.stages.adversarial.common import H, MAP, REF_SAMPLES, W, Case, Result
from wsoft.stages.adversarial.geometry import b_lamp_sphere, b_missing_sublayer, b_room_ceiling, b_sphere

__all__ = ["BASES", "CASES", "H", "KNOWN", "MAP", "REF_SAMPLES", "W", "Case", "Result", "all_dark", "all_lit", "b_lamp_sphere",
           "b_missing_sublayer", "b_room_ceiling", "b_sphere", "close_to", "far_side_dark", "judge", "same_as", "same_as_base",
           "write_stage"]
