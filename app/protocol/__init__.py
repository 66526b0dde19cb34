"""What two processes or two languages must agree on, as pure Python with no I/O."""
