"""Frame sets handed to a worker process through shared memory: a ring of slots, each holding one image per camera.

The process that decodes writes a frame set into a free slot (:meth:`SharedFrames.write`) and sends the worker only
the slot's number and :attr:`SharedFrames.spec`; the worker maps the same memory (:meth:`SharedFrames.attach`) and
reads the images in place (:meth:`SharedFrames.images`), so a set of four 540x960 colour images travels as a few
bytes instead of being pickled, piped and unpickled (docs/speed.md).  Which slots are free is the writer's to keep:
a slot is taken again only once the worker has answered for the set in it.

The writer owns the memory: :meth:`SharedFrames.close` releases it (also after Ctrl-C); a worker only detaches.
"""

from __future__ import annotations

from collections.abc import Sequence
from multiprocessing import shared_memory

import numpy as np

Spec = tuple[str, tuple[tuple[int, ...], ...], int]
"""What a worker attaches with: the shared memory's name, each camera's image shape, the number of slots."""


class SharedFrames:
    """``slots`` frame sets of uint8 images of ``shapes`` (one per camera) in one block of shared memory, made by
    the writer (``name`` None) or attached to by a worker (:meth:`attach`)."""

    def __init__(self, shapes: Sequence[tuple[int, ...]], slots: int, *, name: str | None = None):
        self.shapes = tuple(tuple(int(side) for side in shape) for shape in shapes)
        self.slots = slots
        sizes = [int(np.prod(shape)) for shape in self.shapes]
        self._offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        self._set_size = int(self._offsets[-1])
        self.owner = name is None
        if self.owner:
            self._memory = shared_memory.SharedMemory(create=True, size=max(1, self._set_size * slots))
        else:
            # registered again with the resource tracker the worker shares with its writer (a set of names): the
            # writer's release unregisters it once for both
            self._memory = shared_memory.SharedMemory(name=name)
        buffer = np.ndarray((slots, self._set_size), np.uint8, buffer=self._memory.buf)
        self._views = [
            [
                buffer[slot, start:stop].reshape(shape)
                for start, stop, shape in zip(self._offsets[:-1], self._offsets[1:], self.shapes)
            ]
            for slot in range(slots)
        ]

    @property
    def spec(self) -> Spec:
        """What :meth:`attach` needs in another process."""
        return self._memory.name, self.shapes, self.slots

    @classmethod
    def attach(cls, spec: Spec) -> SharedFrames:
        """The frame sets a writer made, mapped in this process."""
        name, shapes, slots = spec
        return cls(shapes, slots, name=name)

    def fits(self, images: Sequence[np.ndarray]) -> bool:
        """Whether ``images`` have this ring's shapes and type (uint8), camera by camera."""
        return len(images) == len(self.shapes) and all(
            image.dtype == np.uint8 and image.shape == shape for image, shape in zip(images, self.shapes)
        )

    def write(self, slot: int, images: Sequence[np.ndarray]) -> None:
        """Copy a frame set (one image per camera, :meth:`fits`) into ``slot``."""
        assert self.fits(images), "a frame set of other shapes than the ring's"
        for view, image in zip(self._views[slot], images):
            np.copyto(view, image)

    def images(self, slot: int) -> list[np.ndarray]:
        """The images of ``slot``, in place (valid until the slot is written again)."""
        return list(self._views[slot])

    def close(self) -> None:
        """Unmap the memory (left to the garbage collector while an image of it is still held); the writer also
        releases it."""
        self._views = []
        try:
            self._memory.close()
        except BufferError:  # an image handed out is still alive: unmapped with it
            pass
        finally:
            if self.owner:
                self._memory.unlink()
