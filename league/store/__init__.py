"""Content-addressed file stores for model files and race traces.

:mod:`league.store.base` says what a store is (:class:`~league.store.base.FileStore`);
:mod:`league.store.local` keeps files in a folder, :mod:`league.store.s3` in a bucket of
an S3-compatible object store; :mod:`league.store.sweep` clears a store of crash leftovers
and unreferenced files at server start. :func:`open_storage` picks the store the settings
name.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from league.store.base import FileStore
from league.store.local import LocalFileStore

if TYPE_CHECKING:
    from league.settings import Settings


def open_storage(settings: Settings) -> FileStore:
    """The file store ``settings`` name: ``storage_url`` (``s3://bucket/prefix``) or the
    data directory's ``files`` folder."""
    if settings.storage_url:
        from league.store.s3 import S3FileStore  # boto3 only when object storage is used

        return S3FileStore(settings.storage_url, endpoint_url=settings.s3_endpoint_url)
    return LocalFileStore(settings.storage_dir)
