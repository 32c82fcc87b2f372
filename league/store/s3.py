"""Model files and traces in a bucket of an S3-compatible object store (AWS S3, MinIO, Ceph).

Keys follow the local store's layout under the URL's prefix:
``s3://bucket/prefix`` stores ``prefix/<kind>/<ab>/<sha256><suffix>``. A PUT is atomic, so
there are no temp objects; ``If-None-Match: *`` makes it create-only, which tells whether a
call created the object, and an object found already there is copied onto itself to refresh
its ``LastModified`` (the start-up sweep's clock). Reads check the bytes against their sha256.
Credentials and region come from boto3's usual sources (``AWS_ACCESS_KEY_ID``,
``AWS_SECRET_ACCESS_KEY``, ``AWS_REGION``, ``~/.aws``, an instance role). Every failure to
reach the endpoint, find the bucket or be let in is a :class:`StorageError` that says which.
"""

from __future__ import annotations

import hashlib
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any
from urllib.parse import urlsplit

import boto3
from botocore.config import Config
from botocore.exceptions import BotoCoreError, ClientError, NoCredentialsError

from league.store.base import (
    KINDS,
    PROBE_BYTES,
    SHA256,
    TEMP_PREFIX,
    FileStore,
    StorageError,
    address,
    checked,
)

ABSENT = {"NoSuchKey", "404", "NotFound"}
EXISTS = {"PreconditionFailed", "412", "ConditionalRequestConflict"}
CREDENTIALS = {
    "InvalidAccessKeyId",
    "SignatureDoesNotMatch",
    "InvalidToken",
    "ExpiredToken",
    "AuthorizationHeaderMalformed",
}
DENIED = {"AccessDenied", "403", "AllAccessDisabled"}
FULL = {"XMinioStorageFull", "XMinioAdminBucketQuotaExceeded", "QuotaExceeded"}
BotoError = (ClientError, BotoCoreError)


def _code(exc: ClientError) -> str:
    return str(exc.response.get("Error", {}).get("Code", ""))


class S3FileStore(FileStore):
    """The object store at ``url`` (``s3://bucket/prefix``), through ``endpoint_url`` when
    not AWS S3; ``client_options`` go to ``boto3.client`` (credentials, region)."""

    def __init__(self, url: str, endpoint_url: str | None = None, **client_options: Any) -> None:
        parts = urlsplit(url)
        if parts.scheme != "s3" or not parts.netloc:
            raise ValueError(f"not an s3://bucket/prefix URL: {url!r}")
        self.bucket = parts.netloc
        path = parts.path.strip("/")
        self.prefix = f"{path}/" if path else ""
        self.where = f"bucket {self.bucket!r} at {endpoint_url or 'AWS S3'}"
        options: dict[str, Any] = {}
        if endpoint_url:  # MinIO, Ceph...: path-style URLs, checksums only where required
            options = {
                "s3": {"addressing_style": "path"},
                "request_checksum_calculation": "when_required",
                "response_checksum_validation": "when_required",
            }
        retries = {"max_attempts": 3, "mode": "standard"}
        config = Config(connect_timeout=5, read_timeout=60, retries=retries, **options)
        self.client = boto3.client("s3", endpoint_url=endpoint_url, config=config, **client_options)
        self._probe_key = f"{self.prefix}{TEMP_PREFIX}probe-{uuid.uuid4().hex}"

    def key(self, kind: str, sha256: str) -> str:
        """The object key of the file of ``kind`` with this digest."""
        return self.prefix + address(kind, sha256)

    def put(self, kind: str, data: bytes) -> tuple[str, bool]:
        sha256 = hashlib.sha256(data).hexdigest()
        key = self.key(kind, sha256)
        with self._failing(f"could not store a {kind} file"):
            try:
                self.client.put_object(Bucket=self.bucket, Key=key, Body=data, IfNoneMatch="*")
                return sha256, True
            except ClientError as exc:
                if _code(exc) not in EXISTS:
                    raise
            try:
                self._touch(key)
                return sha256, False
            except ClientError as exc:
                if _code(exc) not in ABSENT:
                    raise
            self.client.put_object(Bucket=self.bucket, Key=key, Body=data)  # swept meanwhile
            return sha256, True

    def read(self, kind: str, sha256: str) -> bytes:
        key = self.key(kind, sha256)
        with self._failing(f"could not read a {kind} file"):
            try:
                data = self.client.get_object(Bucket=self.bucket, Key=key)["Body"].read()
            except ClientError as exc:
                if _code(exc) in ABSENT:
                    raise FileNotFoundError(f"no object {key} in {self.where}") from None
                raise
        return checked(kind, sha256, data)

    def remove(self, kind: str, sha256: str) -> None:
        with self._failing(f"could not remove a {kind} file"):
            self.client.delete_object(Bucket=self.bucket, Key=self.key(kind, sha256))

    def objects(self, prefix: str) -> Iterator[tuple[str, float]]:
        """``(key, last modified)`` of every object whose key starts with ``prefix``."""
        with self._failing("could not list the object store"):
            pages = self.client.get_paginator("list_objects_v2")
            for page in pages.paginate(Bucket=self.bucket, Prefix=prefix):
                for item in page.get("Contents", []):
                    yield item["Key"], item["LastModified"].timestamp()

    def remove_temp(self, older_than: float) -> int:
        """Only readiness probes that failed to delete their object leave temp objects."""
        stale = [k for k, t in self.objects(self.prefix + TEMP_PREFIX) if t < older_than]
        with self._failing("could not remove a temp object"):
            for key in stale:
                self.client.delete_object(Bucket=self.bucket, Key=key)
        return len(stale)

    def stored(self, kind: str, older_than: float) -> Iterator[str]:
        folder = f"{self.prefix}{kind}/"
        for key, modified in self.objects(folder):
            group, _, name = key.removeprefix(folder).partition("/")
            sha256 = name.removesuffix(KINDS[kind])
            addressed = name.endswith(KINDS[kind]) and SHA256.match(sha256)
            if addressed and group == sha256[:2] and modified < older_than:
                yield sha256

    def remove_orphan(
        self, kind: str, sha256: str, older_than: float, wanted: Callable[[], bool]
    ) -> bool:
        """S3 cannot rename: the bytes are read, the object deleted and ``wanted()`` asked;
        a wanted file is written back (unless an upload stored it anew meanwhile)."""
        key = self.key(kind, sha256)
        with self._failing(f"could not sweep a {kind} file"):
            try:
                found = self.client.get_object(Bucket=self.bucket, Key=key)
            except ClientError as exc:
                if _code(exc) in ABSENT:  # another server's sweep got there first
                    return False
                raise
            if found["LastModified"].timestamp() >= older_than:  # stored again meanwhile
                return False
            data = found["Body"].read()
            self.client.delete_object(Bucket=self.bucket, Key=key)
            keep = True
            try:
                keep = wanted()
            finally:
                if keep:
                    self._restore(key, data)
            return not keep

    def _restore(self, key: str, data: bytes) -> None:
        try:
            self.client.put_object(Bucket=self.bucket, Key=key, Body=data, IfNoneMatch="*")
        except ClientError as exc:
            if _code(exc) not in EXISTS:
                raise

    def _touch(self, key: str) -> None:
        """Refresh an object's ``LastModified`` (a server-side copy onto itself)."""
        self.client.copy_object(
            Bucket=self.bucket,
            Key=key,
            CopySource={"Bucket": self.bucket, "Key": key},
            MetadataDirective="REPLACE",
            Metadata={"stored-again": f"{time.time():.0f}"},
        )

    def _try_write(self) -> str | None:
        try:
            body = b"\0" * PROBE_BYTES
            self.client.put_object(Bucket=self.bucket, Key=self._probe_key, Body=body)
            self.client.delete_object(Bucket=self.bucket, Key=self._probe_key)
        except BotoError as exc:
            return str(self._error("the object store cannot take a write", exc))
        return None

    @contextmanager
    def _failing(self, action: str) -> Iterator[None]:
        """Turn the client's errors into :class:`StorageError` that say what went wrong."""
        try:
            yield
        except BotoError as exc:
            raise self._error(action, exc) from exc

    def _error(self, action: str, exc: Exception) -> StorageError:
        if isinstance(exc, NoCredentialsError):
            reason = (
                "no S3 credentials found (set AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY, "
                "or another source boto3 reads)"
            )
            return StorageError(action, exc, reason)
        if not isinstance(exc, ClientError):
            return StorageError(action, exc, f"cannot reach {self.where}: {exc}")
        code = _code(exc)
        message = exc.response.get("Error", {}).get("Message", "")
        status = exc.response.get("ResponseMetadata", {}).get("HTTPStatusCode")
        if code == "NoSuchBucket":
            reason = f"{self.where} does not exist"
        elif code in CREDENTIALS:
            reason = f"{self.where} rejected the credentials ({code}: {message})"
        elif code in DENIED:
            reason = f"{self.where} denied access ({code}): check the credentials' permissions"
        else:
            reason = f"{self.where} answered {code}: {message}"
        return StorageError(action, exc, reason, full=code in FULL or status == 507)
