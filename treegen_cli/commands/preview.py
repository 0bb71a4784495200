"""`treegen preview INPUT -o OUT.png`: a headless render of a species or a written tree.

The command's body stays in preview.py for now (beside the renderer it drives); this module is
where the root group finds it, like every other command.
"""

from __future__ import annotations

from ..preview import preview_command as preview

__all__ = ["preview"]
