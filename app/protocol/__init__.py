"""The protocol core: everything two processes or two languages must agree on.

Pure Python with no I/O: message models for the signaling socket and the data channels, and the
constants the browser pages receive through their embedded config. Every other package imports
from here; this package imports from none of them.
"""
