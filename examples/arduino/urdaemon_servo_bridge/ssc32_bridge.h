// ssc32_bridge.h: the part of the urdaemon servo bridge that needs no Arduino.
//
// It reads SSC-32 command lines one byte at a time and turns each complete group into PCA9685
// register writes, through the small Io interface below. The sketch implements Io with Wire and
// Serial; tests/examples/arduino_host/driver.cpp implements it with a printing fake bus, so the same
// code is compiled and checked on the host. Only <stdint.h> is used: no Arduino headers, no heap.
//
// Settings (define them before including this file; the sketch does):
//   BRIDGE_BOARDS          PCA9685 boards, 1..4; channels 0-15 are on the first, 16-31 on the next...
//   BRIDGE_FIRST_ADDRESS   I2C address of the first board; board b answers at this + b
//   BRIDGE_OSCILLATOR_HZ   the PCA9685's oscillator (25 MHz nominal; a calibrated value in whole kHz)
//   BRIDGE_PWM_HZ          output frequency in whole Hz (50 for hobby servos)
//
// Registers, bits and formulas are from the NXP PCA9685 datasheet, rev. 4.

#ifndef SSC32_BRIDGE_H
#define SSC32_BRIDGE_H

#include <stdint.h>

#ifndef BRIDGE_BOARDS
#define BRIDGE_BOARDS 2
#endif
#ifndef BRIDGE_FIRST_ADDRESS
#define BRIDGE_FIRST_ADDRESS 0x40
#endif
#ifndef BRIDGE_OSCILLATOR_HZ
#define BRIDGE_OSCILLATOR_HZ 25000000UL
#endif
#ifndef BRIDGE_PWM_HZ
#define BRIDGE_PWM_HZ 50UL
#endif

namespace ssc32_bridge {

// ---- PCA9685 registers and bits ------------------------------------------------------------------
constexpr uint8_t MODE1 = 0x00;
constexpr uint8_t MODE2 = 0x01;
constexpr uint8_t LED0_ON_L = 0x06;  // channel n: ON_L, ON_H, OFF_L, OFF_H from 0x06 + 4 n
constexpr uint8_t PRE_SCALE = 0xFE;
constexpr uint8_t MODE1_RESTART = 0x80;
constexpr uint8_t MODE1_AI = 0x20;  // auto-increment: one write fills ON_L..OFF_H of a channel
constexpr uint8_t MODE1_SLEEP = 0x10;
constexpr uint8_t MODE2_OUTDRV = 0x04;  // totem-pole outputs
constexpr uint8_t FULL_OFF = 0x10;      // bit 4 of OFF_H: no pulse at all
constexpr uint16_t SETTLE_US = 500;     // oscillator start-up after SLEEP is cleared
constexpr uint16_t RESOLUTION = 4096;   // counts per PWM period

// ---- SSC-32 ranges -----------------------------------------------------------------------------
constexpr uint16_t PULSE_MIN_US = 500;  // the SSC-32 clamps P1..P499 up to this...
constexpr uint16_t PULSE_MAX_US = 2500; // ...and anything above down to this; P0 is "off"

// ---- Derived at compile time -------------------------------------------------------------------
constexpr uint8_t BOARDS = BRIDGE_BOARDS;
constexpr uint8_t CHANNELS = 16 * BOARDS;
constexpr uint32_t OSCILLATOR_HZ = BRIDGE_OSCILLATOR_HZ;
constexpr uint32_t PWM_HZ = BRIDGE_PWM_HZ;
// Four boards (64 channels, a 520-byte line) take about 1.3 KB of an Uno's 2 KB of RAM; more would
// leave no room for the stack.
static_assert(BOARDS >= 1 && BOARDS <= 4, "BRIDGE_BOARDS is 1..4");
static_assert(BRIDGE_FIRST_ADDRESS + BRIDGE_BOARDS - 1 < 0x70, "board addresses run into 0x70 (all-call)");

// PRE_SCALE = round(osc / (4096 f)) - 1 (datasheet equation 1); the chip takes 3..255.
constexpr uint32_t PRESCALE_WIDE = (OSCILLATOR_HZ + RESOLUTION / 2 * PWM_HZ) / (RESOLUTION * PWM_HZ) - 1;
static_assert(PWM_HZ > 0 && PRESCALE_WIDE >= 3 && PRESCALE_WIDE <= 255,
              "the PCA9685 cannot make BRIDGE_PWM_HZ with this oscillator (prescale outside 3..255)");
constexpr uint8_t PRESCALE = PRESCALE_WIDE;

// A pulse of us microseconds is us * f_real * 4096 / 1e6 counts, f_real = osc / (4096 (prescale + 1)),
// which is us * osc / (1e6 (prescale + 1)). The fraction is reduced by gcd(osc, 1e6) so that the
// rounding below is exact in 32-bit integers (no float, no 64-bit division on the AVR).
constexpr uint32_t gcd(uint32_t a, uint32_t b) { return b == 0 ? a : gcd(b, a % b); }
constexpr uint32_t COMMON = gcd(OSCILLATOR_HZ, 1000000UL);
constexpr uint32_t COUNT_NUM = OSCILLATOR_HZ / COMMON;
constexpr uint32_t COUNT_DEN = (1000000UL / COMMON) * (PRESCALE_WIDE + 1);
static_assert(2ULL * PULSE_MAX_US * COUNT_NUM + COUNT_DEN < (1ULL << 32),
              "give BRIDGE_OSCILLATOR_HZ in whole kHz (the count arithmetic would overflow)");

// The longest line kept (whitespace is not stored): every channel as "#nnP2500" and a "T65535".
// A longer line is dropped whole.
constexpr uint16_t LINE_MAX = CHANNELS * 8 + 8;
constexpr uint16_t UNTOUCHED = 0xFFFF;  // a channel the group does not name / never commanded

// The pulse the SSC-32 would make for a P value: 0 stays 0 (off), the rest is clamped.
inline uint16_t clamp_pulse(uint16_t us) {
  if (us == 0) return 0;
  if (us < PULSE_MIN_US) return PULSE_MIN_US;
  if (us > PULSE_MAX_US) return PULSE_MAX_US;
  return us;
}

// OFF count of a pulse (ON is count 0): round half up, within 0..4095.
inline uint16_t count_for(uint16_t us) {
  const uint32_t twice = static_cast<uint32_t>(2) * us * COUNT_NUM;  // fits: see the static_assert
  const uint32_t count = (twice + COUNT_DEN) / (2 * COUNT_DEN);
  return count >= RESOLUTION ? RESOLUTION - 1 : static_cast<uint16_t>(count);
}

// What the bridge needs from the world. The sketch: Wire and Serial. The host test: a printer.
class Io {
 public:
  // One I2C write transaction to a 7-bit address; true when the board acknowledged every byte.
  virtual bool write(uint8_t address, const uint8_t *bytes, uint8_t length) = 0;
  // Busy-wait at least this long.
  virtual void wait_us(uint16_t us) = 0;
  // Send one line of text to the host (the sketch adds the line end).
  virtual void reply(const char *line) = 0;

 protected:
  ~Io() {}
};

// The bridge: feed() it every received byte; a group is applied when its '\r' arrives.
class Bridge {
 public:
  explicit Bridge(Io &io) : io_(io), length_(0), overlong_(false), dropped_(0) {
    for (uint8_t c = 0; c < CHANNELS; ++c) pulse_[c] = UNTOUCHED;
    for (uint8_t b = 0; b < BOARDS; ++b) ready_[b] = false;
  }

  // Start every board and announce the version (a host may wait for that line: the bootloader is done).
  // The channel registers are left alone, so servos keep the pulses they had before a reset.
  void begin() {
    for (uint8_t b = 0; b < BOARDS; ++b) ready_[b] = start_board(b);
    reply_version();
  }

  // One received byte. Spaces, tabs and line feeds are ignored; letters may be either case.
  void feed(char c) {
    if (c == '\r') {
      end_line();
      return;
    }
    if (c == ' ' || c == '\t' || c == '\n') return;
    if (c >= 'a' && c <= 'z') c = static_cast<char>(c - 'a' + 'A');
    if (length_ < LINE_MAX) {
      line_[length_++] = c;
    } else {
      overlong_ = true;
    }
  }

  // Lines dropped since start-up: malformed or overlong (nothing of them was applied).
  uint16_t dropped() const { return dropped_; }

 private:
  Io &io_;
  char line_[LINE_MAX];
  uint16_t length_;
  bool overlong_;
  uint16_t dropped_;
  uint16_t pending_[CHANNELS];  // this group's pulse per channel, or UNTOUCHED
  uint16_t pulse_[CHANNELS];    // the last pulse the host asked for, or UNTOUCHED
  bool ready_[BOARDS];          // started and acknowledging; false: start it before the next write

  static uint8_t address(uint8_t board) { return BRIDGE_FIRST_ADDRESS + board; }

  void end_line() {
    if (overlong_) {
      ++dropped_;
    } else if (length_ == 3 && line_[0] == 'V' && line_[1] == 'E' && line_[2] == 'R') {
      reply_version();
    } else if (parse()) {
      apply();
    } else {
      ++dropped_;
    }
    length_ = 0;
    overlong_ = false;
  }

  // Digits at line_[i...] into value (saturating at 65535); false when there is no digit.
  bool number(uint16_t &i, uint16_t &value) const {
    const uint16_t start = i;
    uint32_t v = 0;
    while (i < length_ && line_[i] >= '0' && line_[i] <= '9') {
      v = v * 10 + static_cast<uint8_t>(line_[i] - '0');
      if (v > 0xFFFF) v = 0xFFFF;
      ++i;
    }
    value = static_cast<uint16_t>(v);
    return i > start;
  }

  // The line as "#<ch>P<us>" repeated, then an optional "T<ms>", into pending_. False on anything
  // else (a channel out of range, a missing number, a stray letter): the caller drops the line whole.
  // T is read and ignored: the bridge moves at once (the daemon sends small steps every cycle).
  bool parse() {
    for (uint8_t c = 0; c < CHANNELS; ++c) pending_[c] = UNTOUCHED;
    uint16_t i = 0;
    uint16_t channel;
    uint16_t value;
    while (i < length_ && line_[i] == '#') {
      ++i;
      if (!number(i, channel) || channel >= CHANNELS) return false;
      if (i >= length_ || line_[i] != 'P') return false;
      ++i;
      if (!number(i, value)) return false;
      pending_[channel] = clamp_pulse(value);
    }
    if (i < length_ && line_[i] == 'T') {
      ++i;
      if (!number(i, value)) return false;
    }
    return i == length_;
  }

  // Write the group, board by board in channel order. A board that is not ready is started first;
  // then it also gets every other pulse it was asked for before (it may have lost power).
  void apply() {
    for (uint8_t b = 0; b < BOARDS; ++b) {
      bool named = false;
      for (uint8_t pin = 0; pin < 16; ++pin) named = named || pending_[16 * b + pin] != UNTOUCHED;
      if (!named) continue;
      const bool restore = !ready_[b];
      if (restore) ready_[b] = start_board(b);
      for (uint8_t pin = 0; pin < 16; ++pin) {
        const uint8_t c = static_cast<uint8_t>(16 * b + pin);
        if (pending_[c] != UNTOUCHED) {
          pulse_[c] = pending_[c];
        } else if (!restore || pulse_[c] == UNTOUCHED) {
          continue;
        }
        // A board that did not start is not written (it would not answer); it is tried again with
        // the next group that names it, and then gets pulse_ in full.
        if (ready_[b] && !write_channel(b, pin, pulse_[c])) ready_[b] = false;
      }
    }
  }

  // One transaction: LEDn_ON_L and the three registers after it (auto-increment), 5 bytes.
  bool write_channel(uint8_t board, uint8_t pin, uint16_t us) {
    uint8_t bytes[5];
    bytes[0] = static_cast<uint8_t>(LED0_ON_L + 4 * pin);
    bytes[1] = 0;  // ON_L, ON_H: the pulse starts at count 0
    bytes[2] = 0;
    if (us == 0) {
      bytes[3] = 0;
      bytes[4] = FULL_OFF;
    } else {
      const uint16_t count = count_for(us);
      bytes[3] = static_cast<uint8_t>(count & 0xFF);
      bytes[4] = static_cast<uint8_t>(count >> 8);
    }
    return io_.write(address(board), bytes, sizeof bytes);
  }

  bool write_register(uint8_t addr, uint8_t reg, uint8_t value) {
    const uint8_t bytes[2] = {reg, value};
    return io_.write(addr, bytes, sizeof bytes);
  }

  // The datasheet's start-up: PRE_SCALE is only taken while asleep; waking needs SETTLE_US before
  // RESTART. All-call stays off (MODE1 has no ALLCALL), so chained boards answer their own address.
  bool start_board(uint8_t board) {
    const uint8_t a = address(board);
    if (!write_register(a, MODE1, MODE1_SLEEP) || !write_register(a, PRE_SCALE, PRESCALE) ||
        !write_register(a, MODE2, MODE2_OUTDRV) || !write_register(a, MODE1, MODE1_AI)) {
      return false;
    }
    io_.wait_us(SETTLE_US);
    return write_register(a, MODE1, MODE1_RESTART | MODE1_AI);
  }

  // "urdaemon-servo-bridge 1.0 boards=2 pwm_hz=50 prescale=121"
  void reply_version() {
    char text[64];
    uint8_t n = 0;
    n = append(text, n, "urdaemon-servo-bridge 1.0 boards=");
    n = append_number(text, n, BOARDS);
    n = append(text, n, " pwm_hz=");
    n = append_number(text, n, PWM_HZ);
    n = append(text, n, " prescale=");
    n = append_number(text, n, PRESCALE);
    text[n] = '\0';
    io_.reply(text);
  }

  static uint8_t append(char *text, uint8_t n, const char *part) {
    while (*part != '\0' && n < 60) text[n++] = *part++;
    return n;
  }

  static uint8_t append_number(char *text, uint8_t n, uint32_t value) {
    char digits[10];
    uint8_t k = 0;
    do {
      digits[k++] = static_cast<char>('0' + value % 10);
      value /= 10;
    } while (value != 0);
    while (k > 0 && n < 60) text[n++] = digits[--k];
    return n;
  }
};

}  // namespace ssc32_bridge

#endif  // SSC32_BRIDGE_H
