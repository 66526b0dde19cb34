"""Pure protocol definitions shared by the server, the simulator, the agent and the pages.

Nothing here does I/O: constants, message models and ROS type names that more than one side
needs, written once.
"""
