"""Safe reading of SSP archives and of their XML files (``.ssd``, ``.ssv``, ``.ssm``).

An SSP file may come from anyone, so its XML is parsed defensively:

* a document type declaration (``<!DOCTYPE``) is refused before parsing, and so is any
  entity declaration: SSP files never need one, and they are what a billion-laughs
  (entity expansion) or an XXE (external entity) attack is made of;
* the parser itself (lxml) is set not to load a DTD, not to substitute entities, not to
  touch the network, and not to lift libxml2's size limits (a second line of defence, for
  encodings that hide the declaration from the byte scan: a tree that still has a DTD is
  refused);
* archive members with an absolute path, a drive letter, a backslash or a ``..`` part are
  refused (Zip Slip), and so is an archive that is not a plain ZIP file.

Every error is an :class:`SspError` naming the file (``archive.ssp!member`` for a member)
and, where the problem is in the XML, the line and the element.
"""
from __future__ import annotations

import posixpath
import re
import zipfile
from pathlib import Path
from typing import Iterator

from lxml import etree

from ..errors import ConfigError

__all__ = ["SspError", "XmlFile", "parse_xml", "check_member_name", "SspArchive", "local_name", "where", "resolve"]

_DECLARATION = re.compile(rb"<!\s*(DOCTYPE|ENTITY)", re.IGNORECASE)


class SspError(ConfigError):
    """An SSP file (or one of its members) that duffid cannot read or honour; the message
    names the file, the line and the element."""


def local_name(element: etree._Element) -> str:
    """The tag of ``element`` without its namespace (``"Connection"``)."""
    return etree.QName(element).localname


class XmlFile:
    """A parsed XML file and its name for messages.

    Attributes
    ----------
    name : str
        The file as messages name it (``"loop.ssp!SystemStructure.ssd"``).
    root : lxml.etree._Element
        The root element (every element carries its ``sourceline``).
    member : str or None
        The archive member (None for a file on disk).
    """

    def __init__(self, name: str, root: etree._Element, member: str | None = None) -> None:
        self.name, self.root, self.member = name, root, member

    def where(self, element: etree._Element) -> str:
        """``"file, line N, <Element name=...>"`` for messages."""
        return where(self.name, element)


def where(name: str, element: etree._Element) -> str:
    """``"file, line N, <Element name='x'>"``: the place of ``element`` in the file ``name``."""
    label = element.get("name")
    tag = local_name(element) + (f" name={label!r}" if label is not None else "")
    return f"{name}, line {element.sourceline}, <{tag}>"


def parse_xml(data: bytes, name: str) -> XmlFile:
    """Parse ``data`` safely (see the module documentation).

    Parameters
    ----------
    data : bytes
        The file's content.
    name : str
        The file as messages name it.

    Returns
    -------
    XmlFile

    Raises
    ------
    SspError
        A DTD or entity declaration (with its line), or XML that is not well formed (with
        line and column).
    """
    found = _DECLARATION.search(data)
    if found is not None:
        line = data.count(b"\n", 0, found.start()) + 1
        kind = found.group(1).decode().upper()
        raise SspError(f"{name}, line {line}: a <!{kind} declaration is refused: SSP files need no DTD, and "
                       "entity declarations are how entity expansion (billion laughs) and external entity "
                       "(XXE) attacks are made")
    parser = etree.XMLParser(resolve_entities=False, load_dtd=False, no_network=True, dtd_validation=False,
                             huge_tree=False, remove_blank_text=False)
    try:
        tree = etree.ElementTree(etree.fromstring(data, parser))
    except etree.XMLSyntaxError as exc:
        line, column = exc.position if exc.position else (getattr(exc, "lineno", 0), 0)
        raise SspError(f"{name}, line {line}, column {column}: not well-formed XML: {exc.msg}") from None
    if tree.docinfo.doctype or tree.docinfo.internalDTD is not None:
        raise SspError(f"{name}: a document type declaration is refused (SSP files need no DTD)")
    return XmlFile(name, tree.getroot())


def check_member_name(archive: str, member: str) -> str:
    """``member`` if it is a safe relative archive path, else :class:`SspError`."""
    parts = member.split("/")
    if member.startswith("/") or "\\" in member or re.match(r"[A-Za-z]:", member) or ".." in parts \
            or "\0" in member:
        raise SspError(f"{archive}: the archive member {member!r} has an absolute path, a drive letter, a "
                       "backslash or a '..' part: refused (it could write or read outside the extraction folder)")
    return member


class SspArchive:
    """An SSP (ZIP) archive whose member names have all been checked.

    Parameters
    ----------
    path : path
        The ``.ssp`` file.

    Raises
    ------
    SspError
        Not a ZIP file, or a member with an unsafe name (every member is checked, used or not).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        try:
            self._zip = zipfile.ZipFile(self.path)
        except (OSError, zipfile.BadZipFile) as exc:
            raise SspError(f"{self.path}: not a readable ZIP archive (an SSP or an FMU): {exc}") from None
        self.names = [check_member_name(str(self.path), info.filename) for info in self._zip.infolist()]

    def __enter__(self) -> SspArchive:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the archive."""
        self._zip.close()

    def label(self, member: str) -> str:
        """``"archive.ssp!member"``."""
        return f"{self.path}!{member}"

    def has(self, member: str) -> bool:
        """Whether ``member`` (a normalised relative path) is in the archive."""
        return member in self.names

    def read(self, member: str) -> bytes:
        """The bytes of ``member``."""
        if member not in self.names:
            raise SspError(f"{self.path}: no member {member!r}")
        return self._zip.read(member)

    def xml(self, member: str) -> XmlFile:
        """The member parsed safely (:func:`parse_xml`)."""
        parsed = parse_xml(self.read(member), self.label(member))
        parsed.member = member
        return parsed

    def extract(self, member: str, folder: Path) -> Path:
        """Write ``member`` under ``folder`` (its checked relative path) and return the file."""
        target = folder / Path(*member.split("/"))
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(self.read(member))
        return target

    def members(self) -> Iterator[str]:
        """Every member name (checked)."""
        return iter(self.names)


def resolve(base: str, reference: str) -> str:
    """The archive-relative path of ``reference`` resolved against the member ``base``
    (``posixpath`` semantics; a result starting with ``../`` lies outside the archive)."""
    return posixpath.normpath(posixpath.join(posixpath.dirname(base), reference))

