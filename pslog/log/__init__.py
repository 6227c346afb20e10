"""The pslog session log: one MCAP file per session (format: docs/log-format.md).

Write with :class:`SessionWriter`, read with :func:`read_session` (never decodes images) and
:func:`iter_images`; summarise with :func:`session_info`; derive a session with
:func:`copy_session`; salvage a truncated one with :func:`recover_session`.
"""

from .copy import copy_session
from .info import session_info
from .reader import Image, Session, iter_images, read_session
from .recover import recover_session
from .writer import SessionWriter

__all__ = ["Image", "Session", "SessionWriter", "copy_session", "iter_images", "read_session",
           "recover_session", "session_info"]
