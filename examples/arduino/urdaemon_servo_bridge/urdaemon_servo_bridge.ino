// urdaemon servo bridge: an Arduino that takes SSC-32 command lines on its serial port and drives
// one or two PCA9685 servo boards over I2C. urdaemon's servo backend talks to it through a `serial`
// output with `protocol: ssc32` (see README.md next to this folder).
//
//   #0P1500#1P1200T20\r   moves channel 0 to 1500 us and channel 1 to 1200 us, both at the '\r'
//   #5P0\r                stops channel 5's pulses (the servo goes limp)
//   VER\r                 answers with a version line
//
// Only the Arduino core and its Wire library are needed. The parsing and the PCA9685 writes are in
// ssc32_bridge.h (no Arduino there, so the host tests compile and run the same code); this file
// connects them to Wire and Serial.

// ---- Settings ------------------------------------------------------------------------------------
#define BRIDGE_BOARDS 2                 // boards at 0x40, 0x41, ...: channels 0-15, 16-31, ...
#define BRIDGE_FIRST_ADDRESS 0x40       // the first board's address (no address jumper closed)
#define BRIDGE_OSCILLATOR_HZ 25000000UL // PCA9685 oscillator; put a measured value here (whole kHz)
#define BRIDGE_PWM_HZ 50UL              // servo frame rate (whole Hz)
#define BRIDGE_BAUD 115200              // must match `baud:` of the cell file's serial output
#define BRIDGE_I2C_HZ 400000UL          // 400 kHz fast mode; use 100000 on long or noisy wires
#define BRIDGE_I2C_TIMEOUT_US 3000      // a stuck bus is reset after this instead of hanging

#include <Wire.h>

#include "ssc32_bridge.h"

// The bridge's view of the hardware.
class WireIo : public ssc32_bridge::Io {
 public:
  // One I2C transaction; Wire's buffer holds 32 bytes, the bridge never sends more than 5.
  bool write(uint8_t address, const uint8_t *bytes, uint8_t length) override {
    Wire.beginTransmission(address);
    Wire.write(bytes, length);
    return Wire.endTransmission() == 0;  // 0: every byte acknowledged
  }

  void wait_us(uint16_t us) override { delayMicroseconds(us); }

  void reply(const char *line) override { Serial.println(line); }  // ends in "\r\n"
};

WireIo io;
ssc32_bridge::Bridge bridge(io);

void setup() {
  Serial.begin(BRIDGE_BAUD);
  Wire.begin();
  Wire.setClock(BRIDGE_I2C_HZ);
  // Off by default in the AVR core: without it a stuck bus would hang the bridge for good.
  // (setWireTimeout came with AVR core 1.8.3; Debian's 1.8.7 has it but not the WIRE_HAS_TIMEOUT macro.)
  Wire.setWireTimeout(BRIDGE_I2C_TIMEOUT_US, true);
  bridge.begin();  // PCA9685 start-up on every board, then the version line
}

void loop() {
  // Serial keeps 64 received bytes; reading them all each pass keeps up with 115200 baud.
  while (Serial.available() > 0) {
    bridge.feed(static_cast<char>(Serial.read()));
  }
}
