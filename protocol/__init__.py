"""Wire contract of sharedctl: CAN (ODrive CANSimple) and Zenoh (MessagePack) codecs. Pure."""
