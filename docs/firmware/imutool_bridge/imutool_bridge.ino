// imutool serial bridge — MPU6050 + HMC5883L (or QMC5883L) over I2C, raw counts to the host.
// Protocol: docs/bridge_protocol.md. Board: any Arduino-compatible MCU with Wire (I2C) and Serial.
// Wiring: SDA/SCL to the sensors (GY-86/GY-87 boards: the magnetometer sits behind the MPU6050; this sketch
// enables the MPU6050's I2C bypass so the host bus sees it). RS-485: put a MAX485 on Serial and tie DE/RE high.
#include <Wire.h>

#define RATE_HZ 200          // frames per second (text variant: ≤ 200 Hz at 115200 baud)
#define BINARY 0             // 1 = 31-byte binary frames (--protocol bridge-binary)
#define USE_QMC5883L 0       // 1 = QMC5883L at 0x0D instead of HMC5883L at 0x1E
const uint8_t MPU = 0x68, HMC = 0x1E, QMC = 0x0D;
const uint8_t ACCEL_FS = 0;  // 0..3 = ±2/4/8/16 g
const uint8_t GYRO_FS = 0;   // 0..3 = ±250/500/1000/2000 °/s
const uint8_t HMC_GAIN = 1;  // 0..7, 1 = 1090 LSB/gauss

uint16_t seq = 0;
uint32_t nextMicros, lastCfg = 0;

void wr(uint8_t addr, uint8_t reg, uint8_t val) {
  Wire.beginTransmission(addr); Wire.write(reg); Wire.write(val); Wire.endTransmission();
}

void rd(uint8_t addr, uint8_t reg, uint8_t *buf, uint8_t n) {
  Wire.beginTransmission(addr); Wire.write(reg); Wire.endTransmission(false);
  Wire.requestFrom(addr, n);
  for (uint8_t i = 0; i < n && Wire.available(); i++) buf[i] = Wire.read();
}

int16_t be16(const uint8_t *p) { return (int16_t)((p[0] << 8) | p[1]); }
int16_t le16(const uint8_t *p) { return (int16_t)((p[1] << 8) | p[0]); }

uint16_t crc16(const uint8_t *d, uint8_t n) {       // CRC-16/CCITT-FALSE
  uint16_t c = 0xFFFF;
  while (n--) { c ^= (uint16_t)(*d++) << 8; for (uint8_t i = 0; i < 8; i++) c = (c & 0x8000) ? (c << 1) ^ 0x1021 : c << 1; }
  return c;
}

void sendText(const char *body) {                    // $body*HH\r\n
  uint8_t x = 0;
  for (const char *p = body; *p; p++) x ^= (uint8_t)*p;
  Serial.print('$'); Serial.print(body); Serial.print('*');
  if (x < 16) Serial.print('0');
  Serial.print(x, HEX); Serial.print("\r\n");
}

void sendConfig() {
  static const int afs[] = {2, 4, 8, 16}, gfs[] = {250, 500, 1000, 2000};
  char b[64];
  if (USE_QMC5883L) snprintf(b, sizeof b, "IMBCFG,mpu6050,%d,%d,qmc5883l,8", afs[ACCEL_FS], gfs[GYRO_FS]);
  else snprintf(b, sizeof b, "IMBCFG,mpu6050,%d,%d,hmc5883l,%d", afs[ACCEL_FS], gfs[GYRO_FS], HMC_GAIN);
  sendText(b);
}

void setup() {
  Serial.begin(115200);
  Wire.begin();
  Wire.setClock(400000);
  wr(MPU, 0x6B, 0x01);                 // wake, PLL clock
  wr(MPU, 0x19, 4);                    // 1 kHz / (1 + 4) = 200 Hz internal rate
  wr(MPU, 0x1A, 3);                    // DLPF 44 Hz
  wr(MPU, 0x1B, GYRO_FS << 3);
  wr(MPU, 0x1C, ACCEL_FS << 3);
  wr(MPU, 0x6A, 0x00); wr(MPU, 0x37, 0x02);   // I2C bypass: reach a magnetometer behind the MPU6050
  if (USE_QMC5883L) { wr(QMC, 0x0B, 0x01); wr(QMC, 0x09, 0x1D); }   // continuous, 200 Hz, ±8 G, OSR 512
  else { wr(HMC, 0x00, 0x78); wr(HMC, 0x01, HMC_GAIN << 5); wr(HMC, 0x02, 0x00); }  // 8 avg, 75 Hz, continuous
  sendConfig();
  nextMicros = micros();
}

void loop() {
  if ((int32_t)(micros() - nextMicros) < 0) return;
  nextMicros += 1000000UL / RATE_HZ;
  uint32_t t = micros();
  uint8_t m[14], g[6];
  int16_t v[10];
  rd(MPU, 0x3B, m, 14);
  v[0] = be16(m); v[1] = be16(m + 2); v[2] = be16(m + 4);
  v[3] = be16(m + 8); v[4] = be16(m + 10); v[5] = be16(m + 12);
  v[9] = be16(m + 6);
  if (USE_QMC5883L) { rd(QMC, 0x00, g, 6); v[6] = le16(g); v[7] = le16(g + 2); v[8] = le16(g + 4); }
  else { rd(HMC, 0x03, g, 6); v[6] = be16(g); v[8] = be16(g + 2); v[7] = be16(g + 4); }  // chip order X, Z, Y
#if BINARY
  uint8_t f[31];
  f[0] = 0xA5; f[1] = 0x5A; f[2] = 26;
  f[3] = seq & 0xFF; f[4] = seq >> 8;
  for (uint8_t i = 0; i < 4; i++) f[5 + i] = (t >> (8 * i)) & 0xFF;
  for (uint8_t i = 0; i < 10; i++) { f[9 + 2 * i] = v[i] & 0xFF; f[10 + 2 * i] = (uint16_t)v[i] >> 8; }
  uint16_t c = crc16(f + 2, 27);
  f[29] = c & 0xFF; f[30] = c >> 8;
  Serial.write(f, 31);
#else
  char b[96];
  snprintf(b, sizeof b, "IMB,%u,%lu,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d", seq, (unsigned long)t,
           v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8], v[9]);
  sendText(b);
#endif
  seq++;
  if (millis() - lastCfg > 10000UL) { lastCfg = millis(); if (!BINARY) sendConfig(); }
}
